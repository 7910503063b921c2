"""
Challenge stages of a trained goal-conditioned controller, for zero-shot transfer:

- :class:`ChooseCheckpoint` chooses the controller's checkpoint on held-out episodes of its own training task (no
  episode of the task it is transferred to), by a stated rule (:func:`choose_checkpoint`);
- :class:`ControllerEvaluation` evaluates it on a task of any package, with no training there, guided by a goal
  planner's landmarks (:class:`~sb3_pilot.LandmarkGuidance`: zero-shot transfer) or unguided (its baseline): the
  ``Pilot/`` tasks and gymnasium-robotics' own (their options, a goal map between the planner's task and the
  controller's, their ``success`` key).
"""

from __future__ import annotations

import json
import re
import shutil
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.save_util import load_from_zip_file
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from sb3_pilot.common.saved_models import vecnormalize_path
from sb3_pilot.common.utils import check_number
from sb3_pilot.distill import GoalMap, GoalPlanner, share_goal_space
from sb3_pilot.envs.locomotion import ant_of, check_same_ant
from sb3_pilot.envs.maze import UMAZE_GOAL_CELL, UMAZE_MAP, UMAZE_START_CELL
from sb3_pilot.experiments.challenges.stages import StageContext, play_episodes
from sb3_pilot.experiments.zoo_run import (
    CARRIED_ENV_KWARGS,
    load_zoo_model,
    training_task,
    with_carried_env_kwargs,
    zoo_saved,
)
from sb3_pilot.transfer import LandmarkGuidance, choose_guidance, horizon_for_lead


def far_umaze_map() -> list[list[int | str]]:
    """
    gymnasium-robotics' ``U_MAZE`` with its reset cell ``"r"`` at one end of the U and its goal cell ``"g"`` at the
    other (:data:`~sb3_pilot.envs.maze.UMAZE_START_CELL`, :data:`~sb3_pilot.envs.maze.UMAZE_GOAL_CELL`): the
    ``maze_map`` option of ``PointMaze_UMaze-v3`` or ``AntMaze_UMaze-v5`` for the far start and goal (their own noise
    on both).
    """
    cells: list[list[int | str]] = [list(row) for row in UMAZE_MAP]
    cells[UMAZE_START_CELL[0]][UMAZE_START_CELL[1]] = "r"
    cells[UMAZE_GOAL_CELL[0]][UMAZE_GOAL_CELL[1]] = "g"
    return cells


def check_controller_ant(model_path: Path, task: gym.Env) -> None:
    """
    Refuse a controller trained on one Ant (``Pilot/...-v0``: gymnasium's) guided on a task of the other (``-v1``: the
    literature's), where its zoo run's saved settings say which task it trained on; warn where nothing says it.

    :param model_path: the controller's zip
    :param task: the task it is to act in
    :raises ValueError: from :func:`~sb3_pilot.envs.locomotion.check_same_ant`
    """
    guided = ant_of(task)
    if guided is None:
        return
    if not zoo_saved(model_path, "args.yml").get("env"):
        warnings.warn(
            f"{model_path} has no zoo settings beside it that say which Ant it was trained on: make sure it is the "
            f"one of the task it is guided on ({guided!r}, sb3_pilot.envs.locomotion.ANT_XML_FILES).",
            stacklevel=2,
        )
        return
    trained = training_task(model_path)
    check_same_ant(trained, task, controller_name=str(model_path))
    trained.close()


def check_controller_inputs(model_path: Path, observation_space: gym.Space, task: gym.Env) -> None:
    """
    Refuse a controller whose observations are not those of the task it is to act in (e.g. an Ant trained without the
    contact forces in its observation, guided on a task that has them), naming the observations that differ.

    :param model_path: the controller's zip (for the message)
    :param observation_space: the controller's observation space
    :param task: the task (guided or not)
    :raises ValueError: if a key or shape differs
    """
    trained, given = observation_space, task.observation_space
    if isinstance(trained, gym.spaces.Dict) and isinstance(given, gym.spaces.Dict):
        keys = sorted(set(trained.spaces) | set(given.spaces))
        shapes = {
            key: (getattr(trained.spaces.get(key), "shape", None), getattr(given.spaces.get(key), "shape", None))
            for key in keys
        }
    else:
        shapes = {"observation": (trained.shape, given.shape)}
    differ = {key: pair for key, pair in shapes.items() if pair[0] != pair[1]}
    if differ:
        named = ", ".join(f"{key}: {old} trained, {new} here" for key, (old, new) in differ.items())
        raise ValueError(
            f"The controller {model_path} sees other observations than this task gives ({named}): build the task with "
            f"the options it trained with (those that change what it sees: {', '.join(CARRIED_ENV_KWARGS)}; its zoo "
            "run's args.yml and config.yml have them)."
        )


def reported_success(info: dict[str, Any]) -> float:
    """SB3's and this package's ``is_success``, else gymnasium-robotics' mazes' ``success``."""
    if "is_success" in info:
        return float(info["is_success"])
    if "success" in info:
        return float(info["success"])
    raise KeyError(f"The task reports no success in its info (no 'is_success' nor 'success' key): {sorted(info)}.")


def controller_episodes(model_path: Path, env: gym.Env, episodes: int, seed: int, algo: str | None = None) -> dict[str, Any]:
    """
    A zoo-saved controller's deterministic episodes on a task, guided (a :class:`~sb3_pilot.LandmarkGuidance`) or not,
    after checking that it is the task's Ant and sees the task's observations (:func:`check_controller_ant`,
    :func:`check_controller_inputs`); episode ``i`` reset with seed ``10_000 * seed + i``.

    :param model_path: the controller (a zoo run's model, its saved settings beside it)
    :param env: the task
    :param episodes: number of episodes
    :param seed: seed of the evaluation
    :param algo: its zoo algorithm (None: from its run)
    :return: ``successes`` (the task's success at each episode's end), ``final_distances`` (to the real goal),
        ``episodes`` (each one's real goal, and with guidance its achieved goals and landmarks) and, with guidance,
        ``horizon``
    """
    controller, vec_normalize = load_zoo_model(model_path, algo=algo)
    check_controller_ant(model_path, env)
    check_controller_inputs(model_path, controller.observation_space, env)
    successes, final_distances, played = [], [], []
    for observation, info in play_episodes(controller, vec_normalize, env, episodes, seed):
        successes.append(reported_success(info))
        goal = np.asarray(info.get("real_desired_goal", observation["desired_goal"]))
        final_distances.append(float(np.linalg.norm(observation["achieved_goal"] - goal)))
        episode = {"desired_goal": goal.tolist()}
        if isinstance(env, LandmarkGuidance):
            episode |= {"achieved_goals": env.episode_achieved_goals.tolist(), "landmarks": env.episode_landmarks.tolist()}
        played.append(episode)
    result: dict[str, Any] = {"successes": successes, "final_distances": final_distances, "episodes": played}
    if isinstance(env, LandmarkGuidance):
        result |= {"horizon": env.horizon, "switch_distance": env.switch_distance}
    return result


@dataclass(frozen=True)
class ControllerEvaluation:
    """
    A controller of an earlier stage on ``env_id`` (made with ``env_kwargs``), with no training there: guided by the
    landmarks of the ``planner`` stage's goal planner (:class:`~sb3_pilot.LandmarkGuidance`, zero-shot transfer), or
    unguided (``planner=None``: the real goal is its ``desired_goal``). The success rate (the task's ``is_success``,
    else its ``success``), the final distances to the real goal and each episode's path (and landmarks) go to
    ``guidance.json``; in the summary, one point at 0 steps on the task.

    :param name: stage name
    :param controller: the :class:`ZooTrain` (or :class:`Shipped`) stage of the controller
    :param env_id: the task it is evaluated on (a Gymnasium ID)
    :param method: label in the summary (None: not a compared method, e.g. a check of the controller alone)
    :param planner: the :class:`Distill` (or :class:`Shipped`) stage of the planner; None: unguided
    :param env_kwargs: options of the task (``gym.make``'s keyword arguments)
    :param goal_scale: the planner's goals map to the task's by this scale (``share_goal_space`` with
        ``GoalMap(goal_scale)`` between the planner's source task and ``env_id``); None: the same coordinates
    :param horizon: chained planner steps to the landmark (``LandmarkGuidance``'s ``horizon``)
    :param lead: if set, ``horizon`` is chosen for each seed's planner instead: the ``k`` whose landmark lies about
        ``lead`` ahead on the task (:func:`~sb3_pilot.transfer.horizon_for_lead`), written to ``guidance.json``
    :param switch_distance: distance to the real goal under which it replaces the landmark (``LandmarkGuidance``'s)
    :param episodes: episodes a seed (None: the budget's ``eval_episodes``); at a budget with steps for this stage
        (``smoke``), the budget's ``eval_episodes``, each ending after that many steps
    :param controller_algo: the zoo algorithm of the controller (None: from its zoo run folder)
    :param compared_with: the stage whose method this one is compared with in the statistics (e.g. the same
        controller unguided); None: SAC+HER, where the challenge has it. Not part of the stage's configuration
    :param max_horizon: with ``lead``, the largest ``k`` considered (a planner of small steps needs more than 10)
    :param choose_switch: with ``lead``, ``k`` and the switch distance chosen together by
        :func:`~sb3_pilot.transfer.choose_guidance` (the task's success radius plus the planner's offset at a goal)
        instead of ``switch_distance``
    """

    name: str
    controller: str
    env_id: str
    method: str | None
    planner: str | None = None
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    goal_scale: float | None = None
    horizon: int = 1
    switch_distance: float | None = None
    episodes: int | None = None
    controller_algo: str | None = None
    compared_with: str | None = None
    lead: float | None = None
    max_horizon: int = 10
    choose_switch: bool = False

    def __post_init__(self) -> None:
        check_number(f"{self.name}: max_horizon", self.max_horizon, minimum=1, integer=True)
        if self.choose_switch and (self.lead is None or self.switch_distance is not None):
            raise ValueError(
                f"{self.name}: choose_switch chooses the switch distance from a lead: give lead, not switch_distance"
            )
        if self.lead is not None:
            check_number(f"{self.name}: lead", self.lead, minimum=0, strict=True)
            if self.planner is None:
                raise ValueError(f"{self.name}: lead chooses the guidance horizon, it needs a planner")

    @property
    def needs(self) -> tuple[str, ...]:
        return (self.controller,) if self.planner is None else (self.planner, self.controller)

    @property
    def rule(self) -> dict[str, Any] | None:
        """The guidance horizon ``k`` and the switch rule, for the summary (None: unguided)."""
        if self.planner is None:
            return None
        switch = (
            "the real goal once it is closer than the landmark"
            if self.switch_distance is None
            else f"the real goal once it is within {self.switch_distance}"
        )
        if self.choose_switch:
            switch = "the real goal once it is within the task's success radius plus the planner's offset at a goal"
        horizon: int | str = self.horizon if self.lead is None else f"chosen per seed: the landmark ~{self.lead} ahead"
        return {"horizon": horizon, "switch_distance": self.switch_distance, "switch_rule": switch}

    def output(self, stage_dir: Path) -> Path:
        """The evaluation's result file."""
        return stage_dir / "guidance.json"

    def n_episodes(self, ctx: StageContext) -> int:
        """The episodes it runs at the context's budget."""
        if self.name in ctx.steps or self.episodes is None:
            return ctx.budget.eval_episodes
        return self.episodes

    def config(self, ctx: StageContext, stage_dir: Path) -> dict[str, Any]:
        return {
            "planner": None if self.planner is None else str(ctx.outputs[self.planner]),
            "controller": str(ctx.outputs[self.controller]),
            "env_id": self.env_id,
            "env_kwargs": self.env_kwargs,
            "goal_scale": self.goal_scale,
            "horizon": self.horizon,
            "switch_distance": self.switch_distance,
            "episodes": self.n_episodes(ctx),
            "max_episode_steps": ctx.steps.get(self.name),
            "seed": ctx.seed,
        } | self._lead_config()

    def _lead_config(self) -> dict[str, Any]:
        """The lead and its largest ``k`` in the configuration only where set: the other stages' hashes stay."""
        if self.lead is None:
            return {}
        return (
            {"lead": self.lead}
            | ({} if self.max_horizon == 10 else {"max_horizon": self.max_horizon})
            | ({"choose_switch": True} if self.choose_switch else {})
        )

    def describe(self, ctx: StageContext, stage_dir: Path) -> str:
        horizon = f"k={self.horizon}" if self.lead is None else f"k for a lead of {self.lead}"
        horizon += ", the switch from the success radius" if self.choose_switch else ""
        guide = "unguided" if self.planner is None else f"guided by {self.planner} ({horizon})"
        return f"{self.controller} on {self.env_id}, {guide}, {self.n_episodes(ctx)} episodes"

    def make_env(self, ctx: StageContext) -> gym.Env:
        """
        The task (its episodes cut at the budget's steps for this stage), with the options of the controller's run that
        decide what it sees and which body moves (:func:`~sb3_pilot.experiments.zoo_run.with_carried_env_kwargs`),
        guided if there is a planner.
        """
        max_steps = ctx.steps.get(self.name)
        env_kwargs = with_carried_env_kwargs(ctx.outputs[self.controller], self.env_id, self.env_kwargs)
        task = gym.make(self.env_id, **env_kwargs, **({"max_episode_steps": max_steps} if max_steps else {}))
        if self.planner is None:
            return task
        planner = GoalPlanner.load(ctx.outputs[self.planner])
        if self.goal_scale is not None:
            share_goal_space(str(planner.source_task), self.env_id, goal_map=GoalMap(self.goal_scale))
        horizon, switch_distance = self.horizon, self.switch_distance
        if self.choose_switch:
            assert self.lead is not None  # checked when the stage was made
            settings = choose_guidance(task, planner, self.lead, max_horizon=self.max_horizon)
            horizon, switch_distance = settings.horizon, settings.switch_distance
        elif self.lead is not None:
            horizon = horizon_for_lead(task, planner, self.lead, max_horizon=self.max_horizon)
        return LandmarkGuidance(task, planner, horizon=horizon, switch_distance=switch_distance)

    def run(self, ctx: StageContext, stage_dir: Path) -> None:
        """Run the controller for :meth:`n_episodes` episodes (deterministic actions)."""
        from sb3_pilot.experiments.zoo import register

        register()  # gymnasium-robotics' tasks, in the stage's process
        env = self.make_env(ctx)
        played = controller_episodes(ctx.outputs[self.controller], env, self.n_episodes(ctx), ctx.seed, self.controller_algo)
        env.close()
        stage_dir.mkdir(parents=True, exist_ok=True)
        planner = None if self.planner is None else str(ctx.outputs[self.planner])
        result = {"planner": planner, "timesteps": [0], "success_rate": [float(np.mean(played["successes"]))], **played}
        self.output(stage_dir).write_text(json.dumps(result))

    def curve(self, stage_dir: Path) -> tuple[list[int], list[float]]:
        """One point: the success rate after 0 steps on the task."""
        result = json.loads(self.output(stage_dir).read_text())
        return result["timesteps"], result["success_rate"]

    def distances(self, stage_dir: Path) -> list[float]:
        """One point: the mean final distance to the real goal."""
        return [float(np.mean(json.loads(self.output(stage_dir).read_text())["final_distances"]))]


#: The rule :class:`ChooseCheckpoint` applies, as its ``choice.json`` states it.
CHOICE_RULE = "highest success rate, ties to the lower mean final distance to the goal, then to the fewer env steps"
#: :class:`ChooseCheckpoint`'s episodes of seed ``k`` are reset with :func:`play_episodes`'s seed ``k + CHOICE_SEED``
#: (``10_000 * (k + CHOICE_SEED) + i``): none of the test episodes' (``10_000 * k + i``), nor the zoo's training seeds.
CHOICE_SEED = 1_000
#: The zoo's checkpoint names (its ``CheckpointCallback``'s, ``--save-freq``).
CHECKPOINT = re.compile(r"rl_model_(\d+)_steps\.zip")


def find_checkpoints(run_dir: Path) -> dict[int, Path]:
    """
    The checkpoints the zoo saved in a run folder (``--save-freq``), and its final model.

    :param run_dir: the zoo's run folder (``<algo>/<env name>_<n>``)
    :return: the models by the env steps they were saved at, sorted (the final model's steps read from its zip; a
        checkpoint saved at the same step is the same model)
    :raise FileNotFoundError: naming the folder, when it holds no checkpoint
    """
    found = {
        int(match[1]): path for path in run_dir.glob("rl_model_*_steps.zip") if (match := CHECKPOINT.fullmatch(path.name))
    }
    if not found:
        raise FileNotFoundError(
            f"No checkpoint (rl_model_<steps>_steps.zip) in {run_dir}: its training kept none. Train the controller "
            "stage with checkpoints (ZooTrain(..., checkpoints=N), the zoo's --save-freq)."
        )
    final = run_dir / f"{run_dir.name.rsplit('_', 1)[0]}.zip"
    if final.is_file():
        data, _, _ = load_from_zip_file(final, custom_objects={}, device="cpu")
        found.setdefault(int(data["num_timesteps"]), final)
    return dict(sorted(found.items()))


def checkpoint_stats(model_path: Path, steps: int) -> Path:
    """
    Where the ``VecNormalize`` statistics of a zoo model are: beside a checkpoint
    (:class:`~sb3_pilot.experiments.zoo_shim.PilotExperimentManager`'s ``rl_model_vecnormalize_<steps>_steps.pkl``),
    in the saved settings of a final model (:func:`vecnormalize_path`).

    :param model_path: the model
    :param steps: the env steps it was saved at
    """
    if CHECKPOINT.fullmatch(model_path.name):
        return model_path.parent / f"rl_model_vecnormalize_{steps}_steps.pkl"
    return vecnormalize_path(model_path)


def choose_checkpoint(scores: list[dict[str, Any]]) -> dict[str, Any]:
    """
    :data:`CHOICE_RULE`: the highest ``success``, ties to the lower ``final_distance``, then to the fewer ``steps``.

    :param scores: each checkpoint's ``steps``, ``success`` (rate) and ``final_distance`` (mean)
    :return: the chosen checkpoint's scores
    :raise ValueError: for no scores
    """
    if not scores:
        raise ValueError("No checkpoint to choose from.")
    return max(scores, key=lambda score: (score["success"], -score["final_distance"], -score["steps"]))


@dataclass(frozen=True)
class ChooseCheckpoint:
    """
    Choose the checkpoint of a controller stage (a :class:`~sb3_pilot.experiments.challenges.stages.ZooTrain` with
    ``checkpoints``) on held-out episodes of its own training task (:func:`training_task`), deterministic actions,
    reset with seeds no test episode uses (:data:`CHOICE_SEED`): no episode of the task it is transferred to. Each
    checkpoint, the final model included, gets its success rate (the task's success at the episode's last step, as
    the zoo's evaluations count it) and mean final distance to the goal; the best by :data:`CHOICE_RULE` is copied
    as the zoo saves a model (``controller.zip`` beside its ``controller/`` folder of saved settings and
    ``VecNormalize`` statistics), which is what the stages naming this one evaluate. Every checkpoint's scores and
    the choice go to ``choice.json``.

    :param name: stage name
    :param controller: the controller's stage (trained with ``checkpoints``)
    :param episodes: held-out episodes per checkpoint; at a budget with steps for this stage (``smoke``), the budget's
        ``eval_episodes``, each ending after that many steps
    """

    name: str
    controller: str
    episodes: int = 30
    method = None

    def __post_init__(self) -> None:
        check_number(f"{self.name}: episodes", self.episodes, minimum=1, integer=True)

    @property
    def needs(self) -> tuple[str, ...]:
        return (self.controller,)

    def output(self, stage_dir: Path) -> Path:
        """The chosen checkpoint, copied."""
        return stage_dir / "controller.zip"

    def n_episodes(self, ctx: StageContext) -> int:
        """The episodes per checkpoint at the context's budget."""
        return ctx.budget.eval_episodes if self.name in ctx.steps else self.episodes

    def config(self, ctx: StageContext, stage_dir: Path) -> dict[str, Any]:
        return {
            "controller": str(ctx.outputs[self.controller]),
            "episodes": self.n_episodes(ctx),
            "max_episode_steps": ctx.steps.get(self.name),
            "seed": ctx.seed + CHOICE_SEED,
            "rule": CHOICE_RULE,
        }

    def describe(self, ctx: StageContext, stage_dir: Path) -> str:
        return f"choose the checkpoint of {self.controller} on {self.n_episodes(ctx)} held-out episodes of its own task"

    def score(self, model_path: Path, stats: Path | None, env: gym.Env, ctx: StageContext) -> dict[str, Any]:
        """
        A checkpoint's held-out episodes.

        :param model_path: the checkpoint
        :param stats: its ``VecNormalize`` statistics (None: the run does not normalise)
        :param env: its training task
        :param ctx: the stage's context
        :return: its success rate and mean final distance to the goal, and those of each episode
        """
        model, _ = load_zoo_model(model_path)
        vec_normalize = None
        if stats is not None:
            vec_normalize = VecNormalize.load(str(stats), DummyVecEnv([lambda: env]))
            vec_normalize.training = False
        successes, distances = [], []
        for observation, info in play_episodes(model, vec_normalize, env, self.n_episodes(ctx), ctx.seed + CHOICE_SEED):
            successes.append(reported_success(info))
            distances.append(float(np.linalg.norm(observation["achieved_goal"] - observation["desired_goal"])))
        return {
            "success": float(np.mean(successes)),
            "final_distance": float(np.mean(distances)),
            "successes": successes,
            "final_distances": distances,
        }

    def run(self, ctx: StageContext, stage_dir: Path) -> None:
        """Score every checkpoint, choose by :data:`CHOICE_RULE`, copy the chosen one, write ``choice.json``."""
        from sb3_pilot.experiments.zoo import register

        register()  # the task may be gymnasium-robotics'
        final = ctx.outputs[self.controller]
        candidates = find_checkpoints(final.parent)  # none: the error names the folder, before any episode
        normalized = vecnormalize_path(final).is_file()
        stats = {steps: checkpoint_stats(path, steps) for steps, path in candidates.items()}
        missing = [str(path) for path in stats.values() if normalized and not path.is_file()]
        if missing:
            raise FileNotFoundError(f"The run {final.parent} normalises its observations, but {missing} are missing.")
        env = training_task(final, ctx.steps.get(self.name))
        scores = []
        for steps, path in candidates.items():
            score = self.score(path, stats[steps] if normalized else None, env, ctx)
            # the models as paths in the seed's folder, which may move
            model = path.relative_to(ctx.seed_dir) if path.is_relative_to(ctx.seed_dir) else path
            scores.append({"steps": steps, "model": str(model), **score})
            print(f"{path.name} ({steps} steps): success {score['success']:.2f}, final distance {score['final_distance']:.2f}")
        env.close()
        chosen = choose_checkpoint(scores)
        print(f"chosen: {chosen['steps']} steps ({CHOICE_RULE})")
        output = self.output(stage_dir)
        saved = vecnormalize_path(output).parent  # the chosen model's saved settings, as the zoo keeps a final model's
        shutil.copytree(final.parent / final.stem, saved, ignore=shutil.ignore_patterns("vecnormalize.pkl"))
        shutil.copyfile(candidates[chosen["steps"]], output)
        if normalized:
            shutil.copyfile(stats[chosen["steps"]], vecnormalize_path(output))
        choice = {"rule": CHOICE_RULE, "episodes": self.n_episodes(ctx), "seed": ctx.seed + CHOICE_SEED}
        choice |= {"chosen": {"steps": chosen["steps"], "model": chosen["model"]}, "checkpoints": scores}
        (stage_dir / "choice.json").write_text(json.dumps(choice, indent=1))
