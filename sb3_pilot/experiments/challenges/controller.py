"""
A challenge stage that evaluates a trained goal-conditioned controller on a task of any package, guided by a goal
planner's landmarks (zero-shot transfer, :class:`~sb3_pilot.LandmarkGuidance`) or unguided (its baseline): the stage
of the ``pointmaze-to-antmaze`` challenge, whose tasks are gymnasium-robotics' own (its options, a goal map between
the planner's task and the controller's, its ``success`` key).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from sb3_pilot.distill import GoalMap, GoalPlanner, share_goal_space
from sb3_pilot.envs.maze import UMAZE_GOAL_CELL, UMAZE_MAP, UMAZE_START_CELL
from sb3_pilot.experiments.challenges.stages import Guidance, StageContext, load_zoo_model, play_episodes
from sb3_pilot.transfer import LandmarkGuidance


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


def reported_success(info: dict[str, Any]) -> float:
    """SB3's and this package's ``is_success``, else gymnasium-robotics' mazes' ``success``."""
    if "is_success" in info:
        return float(info["is_success"])
    if "success" in info:
        return float(info["success"])
    raise KeyError(f"The task reports no success in its info (no 'is_success' nor 'success' key): {sorted(info)}.")


@dataclass(frozen=True)
class ControllerEvaluation:
    """
    A controller of an earlier stage on ``env_id`` (made with ``env_kwargs``), with no training there: guided by the
    landmarks of the ``planner`` stage's goal planner (:class:`~sb3_pilot.LandmarkGuidance`), or unguided
    (``planner=None``: the real goal is its ``desired_goal``). The success rate (the task's ``is_success``, else its
    ``success``), the final distances to the real goal and each episode's path (and landmarks) go to
    ``guidance.json``, as :class:`~sb3_pilot.experiments.challenges.stages.Guidance`'s.

    :param name: stage name
    :param controller: the :class:`ZooTrain` (or :class:`Shipped`) stage of the controller
    :param env_id: the task it is evaluated on (a Gymnasium ID)
    :param method: label in the summary (None: not a compared method, e.g. a check of the controller alone)
    :param planner: the :class:`Distill` (or :class:`Shipped`) stage of the planner; None: unguided
    :param env_kwargs: options of the task (``gym.make``'s keyword arguments)
    :param goal_scale: the planner's goals map to the task's by this scale (``share_goal_space`` with
        ``GoalMap(goal_scale)`` between the planner's source task and ``env_id``); None: the same coordinates
    :param horizon: chained planner steps to the landmark (``LandmarkGuidance``'s ``horizon``)
    :param switch_distance: distance to the real goal under which it replaces the landmark (``LandmarkGuidance``'s)
    :param episodes: episodes a seed (None: the budget's ``eval_episodes``); at a budget with steps for this stage
        (``smoke``), the budget's ``eval_episodes``, each ending after that many steps
    :param controller_algo: the zoo algorithm of the controller (None: from its zoo run folder)
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

    @property
    def needs(self) -> tuple[str, ...]:
        return (self.controller,) if self.planner is None else (self.planner, self.controller)

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
        }

    def describe(self, ctx: StageContext, stage_dir: Path) -> str:
        guide = "unguided" if self.planner is None else f"guided by {self.planner} (k={self.horizon})"
        return f"{self.controller} on {self.env_id}, {guide}, {self.n_episodes(ctx)} episodes"

    def make_env(self, ctx: StageContext) -> gym.Env:
        """The task (its episodes cut at the budget's steps for this stage), guided if there is a planner."""
        max_steps = ctx.steps.get(self.name)
        task = gym.make(self.env_id, **self.env_kwargs, **({"max_episode_steps": max_steps} if max_steps else {}))
        if self.planner is None:
            return task
        planner = GoalPlanner.load(ctx.outputs[self.planner])
        if self.goal_scale is not None:
            share_goal_space(str(planner.source_task), self.env_id, goal_map=GoalMap(self.goal_scale))
        return LandmarkGuidance(task, planner, horizon=self.horizon, switch_distance=self.switch_distance)

    def run(self, ctx: StageContext, stage_dir: Path) -> None:
        """Run the controller for :meth:`n_episodes` episodes (deterministic actions)."""
        from sb3_pilot.experiments.zoo import register

        register()  # gymnasium-robotics' tasks, in the stage's process
        controller, vec_normalize = load_zoo_model(ctx.outputs[self.controller], algo=self.controller_algo)
        env = self.make_env(ctx)
        successes, final_distances, episodes = [], [], []
        for observation, info in play_episodes(controller, vec_normalize, env, self.n_episodes(ctx), ctx.seed):
            successes.append(reported_success(info))
            goal = np.asarray(info.get("real_desired_goal", observation["desired_goal"]))
            final_distances.append(float(np.linalg.norm(observation["achieved_goal"] - goal)))
            episode = {"desired_goal": goal.tolist()}
            if isinstance(env, LandmarkGuidance):
                episode |= {"achieved_goals": env.episode_achieved_goals.tolist(), "landmarks": env.episode_landmarks.tolist()}
            episodes.append(episode)
        env.close()
        stage_dir.mkdir(parents=True, exist_ok=True)
        result = {
            "planner": None if self.planner is None else str(ctx.outputs[self.planner]),
            "timesteps": [0],
            "success_rate": [float(np.mean(successes))],
            "successes": successes,
            "final_distances": final_distances,
        }
        self.output(stage_dir).write_text(json.dumps({**result, "episodes": episodes}))

    # one point each, read from guidance.json as the Guidance stage's
    curve = Guidance.curve
    distances = Guidance.distances
