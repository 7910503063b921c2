"""
The paper's transfer challenges (section 5, "Designed transferring challenges") as stage lists, one challenge per
transfer pair the paper runs (six), and the budgets they run at:

- High-Dim-Action: ``high-dim-action`` (Fetch-Reach -> Fetch-Reach-High-Dim) and ``high-dim-action-push``
  (Fetch-Push -> Fetch-Push-High-Dim): the source UDPO's state planner, frozen, in a target UDPO;
- Vec-to-Image: ``vec-to-image`` (Fetch-Reach -> Fetch-Reach-Image) and ``vec-to-image-reacher`` (Reacher ->
  Reacher-Image): a distilled goal planner's bonus for a pixel-only SAC + HER (:class:`PixelGoalSACPolicy`);
- ``complex-morph`` (Point -> Ant locomotion) and ``zero-shot-ant-maze`` (2D-Maze -> Ant-Maze, zero-shot);

and one pair beyond the paper, cheap enough for ten seeds on a CPU: ``maze-car`` (2D-Maze's point -> a car-like agent in
the same maze, ``Pilot/Maze2DCar-v0``), a bonus challenge like Vec-to-Image's.

Every bonus challenge runs HER + PILoT twice: with the paper's similarity (``goal_cosine``, cosine of the goal
vectors, stage ``pilot``) and with this package's default (``displacement_cosine``, cosine of the achieved and the
planned moves, stage ``pilot_disp``), beside SAC + HER from scratch (stage ``her``).

Step counts: the paper gives none (its figures only show curves), so every count here is our choice. ``paper``
uses the ``n_timesteps`` of the paper-value YAML files (``hyperparams/*.yml``, themselves a choice, see their
headers); ``cpu`` is sized for one long session on 2 cores (measured per seed, 1 torch thread: High-Dim-Action about
3 min, Vec-to-Image on Reacher about 11 min; on a loaded machine, Vec-to-Image on Fetch 17-27 min (its pixel-only
agents ran at 15-26 env steps/s) and High-Dim-Action on Push 69 min; Complex-Morph's
300k-step Ant stages and Zero-shot Ant-Maze's 350k-step controller and baseline 20-45 min each); ``demo`` is ``make
demo``'s (High-Dim-Action only, see :mod:`sb3_pilot.experiments.demo`); ``smoke`` only checks that the pipeline
runs. ``cpu-image`` is Vec-to-Image on Fetch-Reach-Image's verdict budget (:data:`BUDGET_CHALLENGES`, the only challenge
it runs): the cpu budget's source and planner, then SAC + HER and HER + PILoT (displacement cosine) with the pixel recipe
of ``hyperparams/image/`` sized for it (:data:`FETCH_IMAGE_RECIPE`), 100k env steps each (about 65 min of a core),
checkpointed every 10k and resumed across sittings.

Hyperparameters: every zoo stage reads one RL-Zoo YAML entry, its task's in ``hyperparams/<conf_dir><conf_file>``
(``conf_dir``: ``cpu/`` at the smoke, cpu, cpu-image and demo budgets, none at ``paper``) or, at the budgets that read recipes
(all but ``paper``), in the challenge's recipe folder ``hyperparams/cpu/<recipe>/<conf_file>`` where it has that file:
the settings measured to learn quickly on this machine, whose notes are the files' headers; a stage may name its own
folder instead (``ZooTrain.conf_dir``: ``cpu-image``'s arms read ``hyperparams/image/``). One merge rule: the YAML
entry, then the budget's ``hyperparams`` (``smoke``'s small networks), then the stage's ``params`` (paths of earlier
stages' outputs), ``policy_kwargs`` merged key by key (:meth:`~sb3_pilot.experiments.challenges.stages.ZooTrain.zoo_args`).
The same entry trains outside the challenges, e.g. ``python -m sb3_pilot.experiments.zoo train --algo udpo --env
Pilot/FetchReach-v0 --conf-file cpu/fetch/udpo.yml``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

from sb3_pilot.envs.locomotion import ANT_XML_FILES
from sb3_pilot.envs.maze import WallMarginWrapper
from sb3_pilot.experiments.challenges.controller import ChooseCheckpoint, ControllerEvaluation, far_umaze_map
from sb3_pilot.experiments.challenges.stages import (
    REPO_DIR,
    Budget,
    Distill,
    Params,
    Shipped,
    Stage,
    ZooTrain,
)

_CPU = Budget("cpu", conf_dir="cpu/", n_evals=10, eval_episodes=10, distill={"n_samples": 50_000, "gradient_steps": 5_000})

BUDGETS: dict[str, Budget] = {
    "smoke": Budget(
        "smoke",
        conf_dir="cpu/",
        n_evals=2,
        eval_episodes=2,
        distill={"n_samples": 1000, "gradient_steps": 100, "batch_size": 64},
        hyperparams={"learning_starts": 100, "batch_size": 32, "policy_kwargs": {"net_arch": [32, 32]}},
    ),
    "cpu": _CPU,
    # the cpu budget for the stages that run as at cpu (a source, its planner); the stages that differ are the
    # challenge's own at this budget (BUDGET_CHALLENGES)
    "cpu-image": dataclasses.replace(_CPU, name="cpu-image"),
    # make demo: the cpu presets, an evaluation every tenth of a stage (High-Dim-Action's steps["demo"])
    "demo": dataclasses.replace(_CPU, name="demo"),
    "paper": Budget(
        "paper",
        conf_dir="",
        n_evals=20,
        eval_episodes=10,
        distill={"n_samples": 200_000, "gradient_steps": 20_000},
        recipes=False,
    ),
}

#: Encoder of the pixel-only agents at the smoke and cpu budgets, both methods alike (:class:`PixelGoalExtractor`'s
#: ``encoder``, in ``hyperparams/cpu/vec_to_image*/sac*.yml``): chosen by success per wall-clock minute at the cpu budget
#: (zoo_runs/image-encoder/README.md).
IMAGE_ENCODER = "nature"


@dataclass(frozen=True)
class Challenge:
    """
    One transfer challenge: stages run for every seed, in order.

    :param name: CLI name and output folder
    :param description: one line for the README and the plots
    :param target_env: the task the methods are compared on
    :param stages: the stages (a stage may read the outputs of the stages before it)
    :param steps: env steps of each training stage per budget name (a missing budget or stage: the YAML's)
    :param recipe: the challenge's recipe, a folder of RL-Zoo YAML files under the budget's ``conf_dir``
        (``hyperparams/cpu/<recipe>/``) that its zoo stages read at budgets with ``recipes`` where it has their file
        (:meth:`~sb3_pilot.experiments.challenges.stages.ZooTrain.conf_file_at`); None: the budget's files
    """

    name: str
    description: str
    target_env: str
    stages: tuple[Stage, ...]
    steps: dict[str, dict[str, int]]
    recipe: str | None = None

    def __post_init__(self) -> None:
        methods = {stage.name for stage in self.stages if stage.method is not None}
        for stage in self.stages:
            if not isinstance(stage, ControllerEvaluation) or stage.compared_with is None:
                continue
            if stage.method is None or stage.compared_with not in methods - {stage.name}:
                raise ValueError(
                    f"Stage {stage.name!r} of {self.name} is compared with {stage.compared_with!r}: both must be "
                    f"compared methods of it, and differ (those: {sorted(methods)})."
                )


def bonus_params(planner_stage: str, similarity: str) -> Any:
    """
    ``-params`` of a HER + PILoT stage: the bonus wrapper on the planner distilled by ``planner_stage``, with
    ``similarity`` (:data:`~sb3_pilot.transfer.bonus.SIMILARITIES`) written out even where it is the default.
    """

    def params(outputs: dict[str, Path]) -> dict[str, Any]:
        kwargs = {"planner": str(outputs[planner_stage]), "beta": 1.0, "similarity": similarity}
        return {"env_wrapper": [{"sb3_pilot.PilotBonusWrapper": kwargs}]}

    return params


def _state_planner_transfer(outputs: dict[str, Path]) -> dict[str, Any]:
    """``-params`` of the High-Dim target: the source UDPO's state planner, copied when training starts, frozen."""
    return {
        "callback": [{"sb3_pilot.transfer.StatePlannerTransferCallback": {"source": str(outputs["source"])}}],
        "policy_kwargs": {"freeze_state_planner": True},
    }


def _wall_margin(outputs: dict[str, Path]) -> dict[str, Any]:
    """``-params`` of the Maze2D source of Zero-shot Ant-Maze: a step within 1 of a wall costs 2, not 1."""
    return {"env_wrapper": [{f"{WallMarginWrapper.__module__}.{WallMarginWrapper.__qualname__}": {"margin": 1.0}}]}


#: The Maze2D goal planner of Zero-shot Ant-Maze (both Ants). Starts and goals uniform over the maze, so the planner knows
#: its geometry everywhere (the paper queries it from arbitrary start goals); trained on the far goal alone, UDPO saw no
#: success in 12k of its 20k cpu steps and gives a planner with nothing to distil. Steps near a wall cost more
#: (WallMarginWrapper): the point slides along walls for free, the Ant's legs do not.
ZERO_SHOT_PLANNER_STAGES = (
    ZooTrain(
        "maze",
        "udpo",
        "Pilot/Maze2D-v0",
        "udpo.yml",
        params=_wall_margin,
        save_replay_buffer=True,
        env_kwargs={"goal_distribution": "uniform"},
    ),
    Distill("distill", "maze"),
)


def _zero_shot_controller_stages(version: str, checkpoints: int, **guidance: Any) -> tuple[Stage, ...]:
    """
    Zero-shot Ant-Maze's controller stages on the Ant of ``version`` (``Pilot/AntLocomotion-<version>``): the shipped
    controller's recipe (starts and headings anywhere, goals 0.5-3 units away that move on, 500-step episodes ending on
    a flip, goal-relative inputs: zoo_runs/zero-shot-ant-maze/controller), the checkpoint that is guided, chosen on
    held-out episodes of its own open-ground task (no Ant-Maze episode: zero-shot) by success, ties by mean final
    distance (neighbouring checkpoints of one run guided at 0.0 to 0.83: zoo_runs/zero-shot-ant-maze/controller_seed1),
    and its evaluations on ``Pilot/AntMaze-<version>``: guided by the ``distill`` stage's planner, and shown the real
    goal (what the landmarks add).

    :param version: ``"v0"`` (gymnasium's Ant) or ``"v1"`` (the literature's)
    :param checkpoints: checkpoints the controller keeps (:class:`ZooTrain`'s)
    :param guidance: the guided evaluation's ``horizon`` or ``lead`` (:class:`ControllerEvaluation`'s)
    """
    maze = f"Pilot/AntMaze-{version}"
    return (
        ZooTrain("controller", "sac", f"Pilot/AntLocomotion-{version}", "ant_controller_upright.yml", checkpoints=checkpoints),
        ChooseCheckpoint("chosen", "controller", episodes=30),
        ControllerEvaluation(
            "pilot",
            "chosen",
            maze,
            "PILoT zero-shot (0 Ant-Maze steps)",
            planner="distill",
            episodes=30,
            compared_with="unguided",
            **guidance,
        ),
        ControllerEvaluation("unguided", "chosen", maze, "the controller unguided (0 Ant-Maze steps)", episodes=30),
    )


HER, PLANNER_TRANSFER = "SAC+HER (scratch)", "UDPO+PILoT (planner transfer)"
#: MEGA (Pitis et al., 2020) on SAC+HER: the paper's exploration baseline (:mod:`sb3_pilot.baselines`).
HER_MEGA = "SAC+HER+MEGA (baseline)"
#: The two HER + PILoT methods of a bonus challenge: the paper's similarity and this package's default.
PILOT_PAPER, PILOT_DISPLACEMENT = "HER+PILoT (bonus, paper: goal_cosine)", "HER+PILoT (bonus, displacement_cosine)"


def _low_initial_temperature(outputs: dict[str, Path]) -> dict[str, Any]:
    """
    ``-params`` of Fetch-Push's UDPO source: its temperature learnt from 0.1, not SB3's 1. Under its recipe
    (``hyperparams/cpu/fetch_push/``) it ran away after the warm-up from 1 on 2 of 7 seeds (the second the challenge's
    own seed 2, whose run then failed), from 0.1 on none of 6 (``zoo_runs/sources/fetchpush``).
    """
    return {"ent_coef": "auto_0.1"}


def _high_dim_stages(source_env: str, target_env: str, source_params: Params | None = None) -> tuple[Stage, ...]:
    """
    Source UDPO -> its state planner, frozen, in a target UDPO; SAC + HER from scratch on the target.

    :param source_env: the source task
    :param target_env: the target task
    :param source_params: ``-params`` of the source stage only (the target's UDPO keeps the challenge's recipe)
    """
    return (
        ZooTrain("source", "udpo", source_env, "udpo.yml", params=source_params),
        ZooTrain(
            "pilot",
            "udpo",
            target_env,
            "udpo.yml",
            params=_state_planner_transfer,
            needs=("source",),
            method=PLANNER_TRANSFER,
        ),
        ZooTrain("her", "sac", target_env, "sac.yml", method=HER),
    )


def _bonus_stages(
    source_env: str, target_env: str, source_env_kwargs: dict[str, Any] | None = None, target_algo: str = "sac"
) -> tuple[Stage, ...]:
    """
    Source UDPO -> distilled goal planner -> HER + PILoT with the paper's similarity (``pilot``) and with the
    displacement one (``pilot_disp``); SAC + HER from scratch (``her``). Same target YAML values for all three.

    :param source_env: the source task
    :param target_env: the target task
    :param source_env_kwargs: task options of the source (the zoo's ``--env-kwargs``)
    :param target_algo: the zoo algorithm of the three target stages (``sac`` or ``lean_sac``, which reads its YAML)
    """
    return (
        ZooTrain("source", "udpo", source_env, "udpo.yml", save_replay_buffer=True, env_kwargs=source_env_kwargs or {}),
        Distill("distill", "source"),
        ZooTrain(
            "pilot",
            target_algo,
            target_env,
            "sac_pilot.yml",
            params=bonus_params("distill", "goal_cosine"),
            needs=("distill",),
            method=PILOT_PAPER,
        ),
        ZooTrain(
            "pilot_disp",
            target_algo,
            target_env,
            "sac_pilot.yml",
            params=bonus_params("distill", "displacement_cosine"),
            needs=("distill",),
            method=PILOT_DISPLACEMENT,
        ),
        ZooTrain("her", target_algo, target_env, "sac.yml", method=HER),
    )


MAZE_CAR_DESCRIPTION = (
    "UDPO on 2D-Maze (a point) -> distilled goal planner -> HER + bonus on Maze-Car (a car-like agent in the same maze: "
    "speed and turn rate), vs SAC+HER"
)
# uniform starts and goals on both tasks: the planner knows the maze everywhere, and the car's 50-step episodes cannot
# join the two ends of the U (about 24 units at 0.5 a step, and turns)
MAZE_CAR_STAGES = (
    *_bonus_stages("Pilot/Maze2D-v0", "Pilot/Maze2DCar-v0", {"goal_distribution": "uniform"}),
    # the paper's stronger exploration baseline on the same target, its recipe SAC+HER's (hyperparams/cpu/sac_mega.yml)
    ZooTrain("mega", "sac", "Pilot/Maze2DCar-v0", "sac_mega.yml", method=HER_MEGA),
)
MAZE_CAR_STEPS = {
    "smoke": {"source": 300, "pilot": 300, "pilot_disp": 300, "her": 300, "mega": 300},
    # the target's budget was fixed from SAC+HER's runs alone, before any HER+PILoT run (zoo_runs/maze-car-budget/README.md);
    # the source's: Zero-shot Ant-Maze's Maze2D source, which made the shipped plain Maze2D planner
    "cpu": {"source": 20_000, "pilot": 20_000, "pilot_disp": 20_000, "her": 20_000, "mega": 20_000},
}

HIGH_DIM_ACTION_STAGES = _high_dim_stages("Pilot/FetchReach-v0", "Pilot/FetchReachHighDim-v0")
HIGH_DIM_ACTION_STEPS = {
    "smoke": {"source": 400, "pilot": 300, "her": 300},
    "demo": {"source": 8000, "pilot": 4000, "her": 4000},
    "cpu": {"source": 8000, "pilot": 8000, "her": 8000},
}


def _umaze_evaluations(
    controller: str, controller_algo: str | None = None, ant: dict[str, Any] | None = None, **guidance: Any
) -> tuple[ControllerEvaluation, ...]:
    """
    ``pointmaze-to-antmaze``'s evaluations of an Ant controller stage: on ``AntMaze_UMaze-v5`` from the far start to
    the far goal guided by the PointMaze planner (stage ``distill``) and unguided, and on its own open arena.

    :param controller: the controller's stage
    :param controller_algo: its zoo algorithm (None: from its zoo run folder)
    :param ant: options of the three tasks that choose the Ant (``{"xml_file": ...}``; None: gymnasium-robotics')
    :param guidance: the guided evaluation's ``horizon`` or ``lead`` (:class:`ControllerEvaluation`'s; none: k = 12);
        with a ``lead``, a second guided evaluation (``pilot_switch``) chooses ``k`` and the switch to the real goal
        together (``choose_switch``)
    """
    ant = ant or {}
    # the far start and goal; success: gymnasium-robotics' (within 0.45), the episode ending there; the controller's
    # inputs, without contact forces
    far = {"maze_map": far_umaze_map(), "continuing_task": False, "include_cfrc_ext_in_observation": False, **ant}
    # an AntMaze goal is 4 times the PointMaze goal of the same place. k = 12: the lead Zero-shot
    # Ant-Maze's k = 2-3 give its Maze2D planner, 1.1-1.75 Ant units from the far start, where this
    # challenge's seed-0 planner plans 0.10 a step (k = 3: 0.31; k = 12: 1.23; python -m
    # benchmarks.landmark_lead); the switch rule is Zero-shot Ant-Maze's
    guidance = guidance or {"horizon": 12}
    # the switch chosen from the planner and the success radius (sb3_pilot.transfer.choose_guidance), beside the
    # default rule: added to the hrl variant after its seed 0, where 2 of 14 guided failures stopped on a landmark
    # 0.47 and 0.61 from the goal (the default rule never showed it); the verdict stays the `pilot` stage's
    pilot = ControllerEvaluation(
        "pilot",
        controller,
        "AntMaze_UMaze-v5",
        "PILoT zero-shot (0 U-maze steps)",
        planner="distill",
        env_kwargs=far,
        goal_scale=4.0,
        episodes=30,
        controller_algo=controller_algo,
        compared_with="unguided",
        **guidance,
    )
    # with a lead, the same guidance with k and the switch chosen together (choose_guidance) beside it
    switched = (
        (
            dataclasses.replace(
                pilot,
                name="pilot_switch",
                method="PILoT zero-shot, switch from the planner and the success radius (0 U-maze steps)",
                choose_switch=True,
            ),
        )
        if "lead" in guidance
        else ()
    )
    return (
        *switched,
        pilot,
        ControllerEvaluation(
            "unguided",
            controller,
            "AntMaze_UMaze-v5",
            "the controller unguided (0 U-maze steps)",
            env_kwargs=far,
            episodes=30,
            controller_algo=controller_algo,
        ),
        _open_ground(controller, controller_algo, ant),
    )


def _open_ground(controller: str, controller_algo: str | None, ant: dict[str, Any]) -> ControllerEvaluation:
    """The controller on its own task, for scale: open-arena goals of ``AntMaze_Open-v5`` (not a compared method)."""
    return ControllerEvaluation(
        "open_ground",
        controller,
        "AntMaze_Open-v5",
        None,
        env_kwargs={"continuing_task": False, "include_cfrc_ext_in_observation": False, **ant},
        episodes=30,
        controller_algo=controller_algo,
    )


def _maze_evaluations(maze: str, controller: str, ant: dict[str, Any], lead: float, max_horizon: int) -> tuple[Stage, ...]:
    """
    An open-arena Ant controller on ``AntMaze_<maze>-v5`` (gymnasium-robotics' own start and goal cells, drawn anew each
    episode; an episode ends at the goal), guided by the PointMaze planner (stage ``distill``) as
    ``python -m sb3_pilot.experiments.guide`` guides it: ``k`` for a landmark ``lead`` ahead and the switch to the real
    goal chosen together (``choose_switch``); beside it the same controller unguided on the same episodes, and on its
    own open arena.

    :param maze: gymnasium-robotics' map name (``Medium``, ``Large``)
    :param controller: the controller's stage
    :param ant: options of the tasks that choose the Ant (``{"xml_file": ...}``)
    :param lead: the landmark's lead (Ant units)
    :param max_horizon: the largest ``k`` considered
    """
    env_id = f"AntMaze_{maze}-v5"
    task = {"continuing_task": False, "include_cfrc_ext_in_observation": False, **ant}
    return (
        ControllerEvaluation(
            "pilot",
            controller,
            env_id,
            f"PILoT zero-shot (0 {maze}-maze steps)",
            planner="distill",
            env_kwargs=task,
            goal_scale=4.0,
            episodes=30,
            compared_with="unguided",
            lead=lead,
            max_horizon=max_horizon,
            choose_switch=True,
        ),
        ControllerEvaluation(
            "unguided", controller, env_id, f"the controller unguided (0 {maze}-maze steps)", env_kwargs=task, episodes=30
        ),
        _open_ground(controller, None, ant),
    )


def _pointmaze_to_antmaze_stages(
    checkpoints: int, ant: dict[str, Any] | None = None, maze: str = "UMaze", **guidance: Any
) -> tuple[Stage, ...]:
    """
    ``pointmaze-to-antmaze``'s stages: the PointMaze teacher and its planner, the open-arena Ant controller, its
    checkpoint chosen on open ground, and the evaluations (:func:`_umaze_evaluations`, :func:`_maze_evaluations`).

    :param checkpoints: checkpoints the controller keeps (:class:`ZooTrain`'s)
    :param ant: options of the Ant's tasks that choose the Ant (``{"xml_file": ...}``; None: gymnasium-robotics'), for
        training and evaluation alike
    :param maze: gymnasium-robotics' map of the teacher (``PointMaze_<maze>-v3``) and of the guided task
        (``AntMaze_<maze>-v5``); the controller's stages do not depend on it
    :param guidance: the guided evaluation's ``horizon`` or ``lead``
    """
    # the zoo's --env-kwargs replace the YAML entry's: its own, then the Ant
    controller_kwargs = {"max_episode_steps": 500, "include_cfrc_ext_in_observation": False, **ant} if ant else {}
    evaluations = (
        _umaze_evaluations("chosen", ant=ant, **guidance)
        if maze == "UMaze"
        else _maze_evaluations(maze, "chosen", ant or {}, **guidance)
    )
    return (
        # gymnasium-robotics' own tasks under their own IDs: the teacher with sac.yml's PointMaze entry
        ZooTrain("teacher", "sac", f"PointMaze_{maze}-v3", "sac.yml"),
        # beyond the U-maze, rollouts whose goal moves on once reached: PointMaze's teacher otherwise hovers at its goal
        # for most of an episode, and 50k steps give a few dozen start and goal pairs (the Medium teacher's planner
        # learnt little beyond staying put: zoo_runs/pointmaze-to-antmaze-hrl-medium/README.md)
        Distill("distill", "teacher", env_kwargs={} if maze == "UMaze" else {"reset_target": True}),
        # the open-ground controller's recipe (cpu/ant_controller_upright.yml's) through wrappers, ``checkpoints``
        # checkpoints evenly spaced
        ZooTrain(
            "controller",
            "sac",
            "AntMaze_Open-v5",
            "antmaze_open_controller.yml",
            env_kwargs=controller_kwargs,
            checkpoints=checkpoints,
        ),
        # the checkpoint the stages below evaluate: chosen on held-out episodes of its own open-arena task (no
        # U-maze episode), by success, ties by mean final distance
        ChooseCheckpoint("chosen", "controller", episodes=30),
        *evaluations,
    )


#: The smoke budget of ``pointmaze-to-antmaze`` and its variants
_UMAZE_SMOKE = {
    "teacher": 600,
    "controller": 500,
    "chosen": 50,
    "pilot": 50,
    "pilot_switch": 50,
    "unguided": 50,
    "open_ground": 50,
}


CHALLENGES: dict[str, Challenge] = {
    challenge.name: challenge
    for challenge in (
        Challenge(
            "high-dim-action",
            "UDPO on Fetch-Reach -> its state planner, frozen, in a UDPO on Fetch-Reach-High-Dim, vs SAC+HER",
            "Pilot/FetchReachHighDim-v0",
            HIGH_DIM_ACTION_STAGES,
            steps=HIGH_DIM_ACTION_STEPS,
            recipe="fetch",
        ),
        Challenge(
            "high-dim-action-push",
            "UDPO on Fetch-Push -> its state planner, frozen, in a UDPO on Fetch-Push-High-Dim, vs SAC+HER",
            "Pilot/FetchPushHighDim-v0",
            _high_dim_stages("Pilot/FetchPush-v0", "Pilot/FetchPushHighDim-v0", source_params=_low_initial_temperature),
            # cpu: the steps in which SAC + HER and UDPO learnt Fetch-Push with its recipe (hyperparams/cpu/fetch_push/)
            steps={
                "smoke": {"source": 1200, "pilot": 1200, "her": 1200},
                "cpu": {"source": 150_000, "pilot": 150_000, "her": 150_000},
            },
            recipe="fetch_push",
        ),
        Challenge(
            "vec-to-image",
            "UDPO on Fetch-Reach (vector) -> distilled goal planner -> HER + bonus on Fetch-Reach-Image (pixels and "
            "desired goal only), vs SAC+HER",
            "Pilot/FetchReachImage-v0",
            _bonus_stages("Pilot/FetchReach-v0", "Pilot/FetchReachImage-v0"),
            steps={
                "smoke": {"source": 300, "pilot": 200, "pilot_disp": 200, "her": 200},
                "cpu": {"source": 8000, "pilot": 8000, "pilot_disp": 8000, "her": 8000},
            },
            recipe="vec_to_image",
        ),
        Challenge(
            "vec-to-image-reacher",
            "UDPO on Reacher (vector) -> distilled goal planner -> HER + bonus on Reacher-Image (pixels and desired "
            "goal only), vs SAC+HER",
            "Pilot/ReacherImage-v0",
            _bonus_stages("Pilot/Reacher-v0", "Pilot/ReacherImage-v0"),
            steps={
                "smoke": {"source": 800, "pilot": 400, "pilot_disp": 400, "her": 400},
                "cpu": {"source": 40_000, "pilot": 8000, "pilot_disp": 8000, "her": 8000},
            },
            recipe="vec_to_image_reacher",
        ),
        Challenge(
            "complex-morph",
            "UDPO on Point-Locomotion -> distilled goal planner -> HER + bonus on Ant-Locomotion, vs SAC+HER",
            "Pilot/AntLocomotion-v0",
            (
                *_bonus_stages("Pilot/PointLocomotion-v0", "Pilot/AntLocomotion-v0", target_algo="lean_sac"),
                ZooTrain("mega", "lean_sac", "Pilot/AntLocomotion-v0", "sac_mega.yml", method=HER_MEGA),
            ),
            steps={
                "smoke": {"source": 2100, "pilot": 500, "pilot_disp": 500, "her": 500, "mega": 500},
                # the target's budget from SAC + HER's own curve under its recipe (hyperparams/cpu/complex_morph/), fixed
                # before any HER + PILoT run with it: 0.20 of the goals at 150k (one seed), 0.45 at 250k (another), so ~50% is
                # passed near 300k. The source's: UDPO reaches 90% on Point-Locomotion at ~53k steps (IQM of 3 seeds,
                # zoo_runs/sources/lambda), so 80k gives the planner a source that has learned
                "cpu": {"source": 80_000, "pilot": 300_000, "pilot_disp": 300_000, "her": 300_000, "mega": 300_000},
            },
            recipe="complex_morph",
        ),
        Challenge(
            "maze-car",
            MAZE_CAR_DESCRIPTION,
            "Pilot/Maze2DCar-v0",
            MAZE_CAR_STAGES,
            steps=MAZE_CAR_STEPS,
            recipe="maze_car",
        ),
        Challenge(
            "wall-maze-car",
            "SAC+HER on the walled maze (a point) -> goal planner distilled from its steps -> HER + bonus on the walled "
            "maze's car (speed and turn rate), vs SAC+HER; and its landmarks guiding a car controller of the open square "
            "across the wall (0 walled-maze steps), vs the same controller unguided",
            "Pilot/WallMaze2DCar-v0",
            (
                # the teacher is SAC + HER, which learns the detour round the wall where UDPO is slower
                # (docs/results/sources.md); the bonus needs only a teacher that reaches goals. Every stage takes the
                # YAML's walled-maze entries (the settings SAC + HER was measured to learn the point's detour with)
                ZooTrain("teacher", "sac", "Pilot/WallMaze2D-v0", "sac.yml"),
                Distill("distill", "teacher"),  # the budget's distil arguments: labels from the teacher's rollouts
                ZooTrain(
                    "pilot_disp",
                    "sac",
                    "Pilot/WallMaze2DCar-v0",
                    "sac_pilot.yml",
                    params=bonus_params("distill", "displacement_cosine"),
                    needs=("distill",),
                    method=PILOT_DISPLACEMENT,
                ),
                ZooTrain("her", "sac", "Pilot/WallMaze2DCar-v0", "sac.yml", method=HER),
                # zero-shot: a car controller of the open square (the walled car's task and settings without the wall),
                # evaluated with starts and goals on opposite sides of the wall (across=True), never trained there
                ZooTrain("controller", "sac", "Pilot/WallMaze2DCar-v0", "sac.yml", env_kwargs={"wall": False}),
                # k = 1: a landmark one teacher step ahead is a place the point reached from here in one straight
                # move, so the car, which drives straight at its goal, meets no wall on the way; beyond the wall's top
                # (a 0.1-wide wall, a U-turn) a landmark k >= 2 steps ahead (up to 0.2 per axis a step) lies across
                # the wall in a straight line from a car below the top, where a blocked move leaves the car in place.
                # One step is longer than the 0.1 success distance (benchmarks/wall_landmarks.py measures it), so the
                # controller does not stop short at a landmark
                ControllerEvaluation(
                    "guided",
                    "controller",
                    "Pilot/WallMaze2DCar-v0",
                    "PILoT zero-shot (0 walled-maze steps)",
                    planner="distill",
                    env_kwargs={"across": True},
                    horizon=1,
                    episodes=30,
                    compared_with="unguided",
                ),
                ControllerEvaluation(
                    "unguided",
                    "controller",
                    "Pilot/WallMaze2DCar-v0",
                    "the open-square controller unguided (0 walled-maze steps)",
                    env_kwargs={"across": True},
                    episodes=30,
                ),
            ),
            steps={
                "smoke": {"teacher": 300, "pilot_disp": 300, "her": 300, "controller": 300, "guided": 30, "unguided": 30},
                # the teacher's: SAC + HER reached 90% cross-wall success on the point at ~10k steps (16 of 16 seeds).
                # The car's: where SAC + HER's own curve has flattened, sized before any PILoT run (past 0.5 at
                # 3-6k, about 0.9 from 15k on, 2 seeds to 60k: zoo_runs/wall-maze-car-budget); the controller's: the
                # her stage's
                "cpu": {"teacher": 20_000, "pilot_disp": 15_000, "her": 15_000, "controller": 15_000},
            },
        ),
        Challenge(
            "pointmaze-to-antmaze",
            "SAC+HER on PointMaze_UMaze-v3 -> goal planner from its steps, GoalMap(4.0) -> landmarks for an Ant "
            "controller of the open arena AntMaze_Open-v5 on AntMaze_UMaze-v5, far start to far goal (0 U-maze steps), "
            "vs the same controller unguided",
            "AntMaze_UMaze-v5",
            # a checkpoint kept every seventh of the controller's steps (every 50k at the cpu budget)
            _pointmaze_to_antmaze_stages(checkpoints=7),
            steps={
                "smoke": _UMAZE_SMOKE,
                # the teacher's is sac.yml's PointMaze budget: from the U's far start cell to its far goal cell,
                # seed 0's teacher reached the goal in 0.15 of 20 episodes at 50k steps and 1.00 at 100k
                # (python -m benchmarks.umaze_teacher; zoo_runs/pointmaze-to-antmaze). The controller's: the upright
                # recipe's best-guiding checkpoint on Pilot/AntLocomotion-v0
                "cpu": {"teacher": 100_000, "controller": 350_000},
            },
        ),
        Challenge(
            "zero-shot-ant-maze",
            "UDPO on 2D-Maze (wall margin 1) -> distilled goal planner guiding an open-ground SAC Ant controller "
            "(cpu/ant_controller_upright.yml) on Ant-Maze (0 Ant-Maze steps), vs the same controller unguided and "
            "SAC+HER trained on Ant-Maze for as many steps",
            "Pilot/AntMaze-v0",
            (
                *ZERO_SHOT_PLANNER_STAGES,
                # k = 3, measured on this challenge's seed-0 controller and planner (a planner distilled from the
                # teacher's real steps, 0.42 a step): success k = 1 / 2 / 3 0.23 / 0.47 / 0.67 on seeds 0-2, k = 2 / 3
                # / 4 0.63 / 0.63 / 0.30 on held-out seeds 3-5 (zoo_runs/zero-shot-ant-maze-earlier-presets/README.md);
                # a checkpoint kept every seventh of its steps (every 50k at the cpu budget)
                *_zero_shot_controller_stages("v0", checkpoints=7, horizon=3),
                ZooTrain("her", "sac", "Pilot/AntMaze-v0", "sac.yml", method=HER),
                # the paper's exploration baseline trained on Ant-Maze, SAC+HER's recipe (hyperparams/cpu/sac_mega.yml)
                ZooTrain("mega", "sac", "Pilot/AntMaze-v0", "sac_mega.yml", method=HER_MEGA),
            ),
            steps={
                # smoke: the budget's few episodes for the evaluations, of the task's own 500 steps
                "smoke": {
                    "maze": 300,
                    "controller": 500,
                    "chosen": 50,
                    "pilot": 500,
                    "unguided": 500,
                    "her": 2100,
                    "mega": 2100,
                },
                # the controller stops at 350k of its YAML's 4.5e5: the step count whose checkpoint guided best when the
                # recipe was made (hyperparams/cpu/ant_controller_upright.yml's header); training on to 450k was not a
                # measured gain (zoo_runs/zero-shot-ant-maze/controller_450k)
                "cpu": {"maze": 20_000, "controller": 350_000, "her": 350_000, "mega": 350_000},
            },
        ),
        Challenge(
            "zero-shot-ant-maze-v1",
            "UDPO on 2D-Maze (wall margin 1) -> distilled goal planner guiding an open-ground SAC controller of the "
            "literature's Ant (cpu/ant_controller_upright.yml on Pilot/AntLocomotion-v1) on Ant-Maze-v1 (0 Ant-Maze "
            "steps), vs the same controller unguided",
            "Pilot/AntMaze-v1",
            (
                # the v0 challenge's planner stages, unchanged (the planner knows nothing of the Ant)
                *ZERO_SHOT_PLANNER_STAGES,
                # the v0 challenge's recipe on the literature's Ant (its YAML entry: the same settings), a checkpoint
                # every 50k steps at the cpu budget; the horizon of each seed's planner: its landmark about 2.75 units
                # ahead, the lead that guided the sizing controllers best on average
                # (zoo_runs/ant-v1-controller/README.md)
                *_zero_shot_controller_stages("v1", checkpoints=4, lead=2.75),
            ),
            steps={
                "smoke": {"maze": 300, "controller": 500, "chosen": 50, "pilot": 500, "unguided": 500},
                # the controller's budget from its sizing runs (zoo_runs/ant-v1-controller/README.md), fixed before
                # any of this challenge's seeds
                "cpu": {"maze": 20_000, "controller": 200_000},
            },
        ),
    )
}

#: The pixel recipe of Vec-to-Image on Fetch-Reach-Image's verdict, sized for SAC + HER and HER + PILoT together to 100k
#: env steps before any verdict seed (zoo_runs/fetch-image-sizing/README.md): ``hyperparams/image/``'s entries
#: (pixel-only PixelGoalSACPolicy, NatureCNN, DrQ's random shift 4, minibatches of 64, a gradient step per 2 env steps),
#: the target hidden from the frame and the frames drawn without multisampling (``benchmarks.image_recipe``'s ``hidden``
#: and ``cheap``), an evaluation of 20 episodes every 5k env steps; a resumable checkpoint every 10k, so that a stage
#: (about 65 min of a core) crosses sittings. :class:`ZooTrain` settings, each in a stage's command only where set.
FETCH_IMAGE_RECIPE: dict[str, Any] = {
    "conf_dir": "image/",
    "env_kwargs": {"show_target": False, "antialias": False},
    "eval_freq": 5000,
    "eval_episodes": 20,
    "checkpoint_freq": 10_000,
}


def _fetch_image_verdict(challenge: Challenge) -> Challenge:
    """
    Vec-to-Image on Fetch-Reach-Image at the ``cpu-image`` budget: the cpu budget's source and planner (their hashes
    the same), then the two sized arms with :data:`FETCH_IMAGE_RECIPE`, 100k env steps each; the paper's similarity
    (stage ``pilot``) was not sized and does not run.

    :param challenge: ``vec-to-image``
    """
    arms = ("pilot_disp", "her")
    stages = tuple(
        dataclasses.replace(stage, **FETCH_IMAGE_RECIPE) if stage.name in arms else stage
        for stage in challenge.stages
        if stage.name != "pilot"
    )
    steps = {"source": challenge.steps["cpu"]["source"], **dict.fromkeys(arms, 100_000)}
    return dataclasses.replace(challenge, stages=stages, steps={"cpu-image": steps})


#: Budgets at which challenges run stages of their own (other recipes), by budget and challenge name: the challenge as
#: it runs at that budget (the same folder). Such a budget runs these challenges only.
BUDGET_CHALLENGES: dict[str, dict[str, Challenge]] = {
    "cpu-image": {"vec-to-image": _fetch_image_verdict(CHALLENGES["vec-to-image"])},
}


def at_budget(challenge: Challenge, budget: str) -> Challenge:
    """
    :param challenge: a challenge
    :param budget: a budget's name
    :return: the challenge as it runs at ``budget``: its own stages there (:data:`BUDGET_CHALLENGES`), else itself
    """
    return BUDGET_CHALLENGES.get(budget, {}).get(challenge.name, challenge)


#: ``--variant``: other settings of a challenge, each a challenge of its own (its folder ``<challenge>-<variant>``), by
#: challenge and variant name.
VARIANTS: dict[str, dict[str, Challenge]] = {
    "pointmaze-to-antmaze": {
        # the hierarchical-RL literature's Ant (Pilot/AntLocomotion-v1's) in gymnasium-robotics' own tasks, through
        # their xml_file: the recipe, budget (200k) and lead (2.75 Ant units; k up to 100 for this planner's
        # ~0.1-unit steps) of zero-shot-ant-maze-v1's controller, sized on that Ant (zoo_runs/ant-v1-controller),
        # a checkpoint every 50k steps
        "hrl": Challenge(
            "pointmaze-to-antmaze-hrl",
            "SAC+HER on PointMaze_UMaze-v3 -> goal planner from its steps, GoalMap(4.0) -> landmarks for a controller "
            "of the literature's Ant (xml_file: sb3_pilot's ant_hrl.xml) on the open arena AntMaze_Open-v5, guided on "
            "AntMaze_UMaze-v5 with that Ant, far start to far goal (0 U-maze steps), vs the same controller unguided",
            "AntMaze_UMaze-v5",
            _pointmaze_to_antmaze_stages(checkpoints=4, ant={"xml_file": ANT_XML_FILES["hrl"]}, lead=2.75, max_horizon=100),
            steps={"smoke": _UMAZE_SMOKE, "cpu": {"teacher": 100_000, "controller": 200_000}},
        ),
        # issue 60's Medium pair: the hrl variant's controller stages unchanged (the same hashes: its finished
        # controllers serve here), the teacher on PointMaze_Medium-v3 with the same recipe and budget, guided on
        # AntMaze_Medium-v5's own cells as the guide command guides (k and the switch chosen together)
        "hrl-medium": Challenge(
            "pointmaze-to-antmaze-hrl-medium",
            "SAC+HER on PointMaze_Medium-v3 -> goal planner from its steps, GoalMap(4.0) -> landmarks for the hrl "
            "variant's controller (the literature's Ant on AntMaze_Open-v5), guided on AntMaze_Medium-v5 with that Ant, "
            "its own start and goal cells (0 Medium-maze steps), vs the same controller unguided",
            "AntMaze_Medium-v5",
            _pointmaze_to_antmaze_stages(
                checkpoints=4, ant={"xml_file": ANT_XML_FILES["hrl"]}, maze="Medium", lead=2.75, max_horizon=100
            ),
            steps={"smoke": _UMAZE_SMOKE, "cpu": {"teacher": 100_000, "controller": 200_000}},
        ),
    },
}


def challenge_variant(name: str, variant: str) -> Challenge:
    """
    :param name: a challenge's name
    :param variant: one of its variants (:data:`VARIANTS`)
    :return: the variant's challenge
    :raise ValueError: naming the variants there are, for a challenge without ``variant``
    """
    variants = VARIANTS.get(name, {})
    if variant not in variants:
        known = ", ".join(f"{challenge} --variant {v}" for challenge, names in VARIANTS.items() for v in names)
        raise ValueError(f"{name} has no variant {variant!r}; the variants: {known}")
    return variants[variant]


#: The controller and planners shipped for Zero-shot Ant-Maze (see the README there for how each was made).
SHIPPED_DIR = REPO_DIR / "zoo_runs" / "zero-shot-ant-maze" / "controller"
#: The controller and planner shipped for Zero-shot Ant-Maze on the literature's Ant (``zero-shot-ant-maze-v1``'s
#: training seed 1; ``zoo_runs/zero-shot-ant-maze-v1/shipped/README.md``).
SHIPPED_V1_DIR = REPO_DIR / "zoo_runs" / "zero-shot-ant-maze-v1" / "shipped"
#: The Maze2D goal planner Maze-Car's ``--reuse-shipped`` run shares between its seeds.
MAZE_CAR_PLANNER = SHIPPED_DIR / "maze2d_planner.pt"
#: The trained sources shipped in the repository, laid out as the zoo saves a run (``zoo_runs/sources/shipped/README.md``
#: says how each was made), each with its ``VecNormalize``: UDPO on Fetch-Reach (the sources benchmark's recipe, seed 0)
#: and on Fetch-Push (``hyperparams/cpu/fetch_push/``, seed 0).
SOURCES_DIR = REPO_DIR / "zoo_runs" / "sources" / "shipped"
FETCH_REACH_SOURCE = SOURCES_DIR / "fetchreach_seed0" / "udpo" / "Pilot-FetchReach-v0_1" / "Pilot-FetchReach-v0.zip"
#: UDPO on Fetch-Push with its recipe ``hyperparams/cpu/fetch_push/`` (lambda 1e-4, 50k warm-up steps), seed 0, its
#: 150k-step checkpoint.
FETCH_PUSH_SOURCE = SOURCES_DIR / "fetchpush_seed0" / "udpo" / "Pilot-FetchPush-v0_1" / "Pilot-FetchPush-v0.zip"
#: The PointMaze goal planner and the open-arena Ant controller shipped for ``pointmaze-to-antmaze`` (one training seed of
#: that challenge: its ``distill`` stage's planner and its ``chosen`` stage's checkpoint; ``shipped/README.md`` there).
UMAZE_SHIPPED_DIR = REPO_DIR / "zoo_runs" / "pointmaze-to-antmaze" / "shipped"


def _shipped_planner_transfer(outputs: dict[str, Path], net_arch: list[int]) -> dict[str, Any]:
    """
    :func:`_state_planner_transfer` of a shipped source: the target's networks are the source's size at every budget.

    :param outputs: the finished stages' outputs
    :param net_arch: the shipped source's hidden layers
    """
    transfer = _state_planner_transfer(outputs)
    return {**transfer, "policy_kwargs": {**transfer["policy_kwargs"], "net_arch": net_arch}}


def _from_shipped_source(challenge: Challenge, description: str, source: Path, net_arch: list[int]) -> Challenge:
    """
    A High-Dim-Action challenge whose every seed's target reuses the state planner of one shipped source: no source
    stage trains.

    :param challenge: the challenge (stages ``source``, ``pilot``, then the baselines)
    :param description: the new challenge's description
    :param source: the shipped source's zoo model (its ``VecNormalize`` beside it)
    :param net_arch: the shipped source's hidden layers, the target's at every budget
    """
    _, pilot, *baselines = challenge.stages
    return dataclasses.replace(
        challenge,
        name=f"{challenge.name}-shipped",
        description=description,
        stages=(
            Shipped("source", source),
            dataclasses.replace(pilot, params=partial(_shipped_planner_transfer, net_arch=net_arch)),
            *baselines,
        ),
        steps={
            budget: {name: n for name, n in steps.items() if name != "source"} for budget, steps in challenge.steps.items()
        },
    )


#: ``--reuse-shipped``: challenges that evaluate the shipped models instead of training them, by challenge name.
REUSE_SHIPPED: dict[str, Challenge] = {
    "zero-shot-ant-maze": Challenge(
        "zero-shot-ant-maze-shipped",
        "the shipped Maze2D goal planner (UDPO, wall margin 1) guiding the shipped open-ground SAC Ant controller "
        "(cpu/ant_controller_upright.yml, training seed 1, 400k steps) on Ant-Maze (0 Ant-Maze steps, no training stage)",
        "Pilot/AntMaze-v0",
        (
            Shipped("distill", SHIPPED_DIR / "maze2d_planner_margin1.pt"),
            # its checkpoint chosen on open ground only (zoo_runs/zero-shot-ant-maze/controller_seed1/README.md)
            Shipped("controller", SHIPPED_DIR / "ant_controller_upright_seed1_sac_400k.zip"),
            # k and the switch rule chosen with the training-seed-0 controller and this planner (controller/README.md):
            # k = 1 and k = 2 tie on success (0.70 on seeds 0-2, 0.60 on seeds 3-5); k = 1 flips less
            ControllerEvaluation(
                "pilot",
                "controller",
                "Pilot/AntMaze-v0",
                "PILoT zero-shot, shipped models (0 Ant-Maze steps)",
                planner="distill",
                horizon=1,
                controller_algo="sac",
            ),
        ),
        steps={"smoke": {"pilot": 50}},  # smoke: 50-step episodes
    ),
    # one training seed of zero-shot-ant-maze-v1 (the seed whose guided score was best: a demonstration, not a verdict)
    "zero-shot-ant-maze-v1": Challenge(
        "zero-shot-ant-maze-v1-shipped",
        "the shipped Maze2D goal planner (UDPO, wall margin 1) guiding the shipped open-ground SAC controller of the "
        "literature's Ant (cpu/ant_controller_upright.yml on Pilot/AntLocomotion-v1, 200k steps) on Ant-Maze-v1 "
        "(0 Ant-Maze steps, no training stage), vs the same controller unguided",
        "Pilot/AntMaze-v1",
        (
            Shipped("distill", SHIPPED_V1_DIR / "maze2d_planner_seed1.pt"),
            Shipped("chosen", SHIPPED_V1_DIR / "ant_v1_controller_seed1_sac_200k.zip"),
            ControllerEvaluation(
                "pilot",
                "chosen",
                "Pilot/AntMaze-v1",
                "PILoT zero-shot, shipped models (0 Ant-Maze steps)",
                planner="distill",
                episodes=30,
                lead=2.75,
                compared_with="unguided",
            ),
            ControllerEvaluation(
                "unguided", "chosen", "Pilot/AntMaze-v1", "the controller unguided (0 Ant-Maze steps)", episodes=30
            ),
        ),
        steps={"smoke": {"pilot": 50, "unguided": 50}},  # smoke: 50-step episodes
    ),
    # one source for every seed: the shipped Fetch-Reach UDPO, whose state planner every seed's target reuses
    "high-dim-action": _from_shipped_source(
        CHALLENGES["high-dim-action"],
        "the shipped Fetch-Reach UDPO's state planner, frozen, in a UDPO on Fetch-Reach-High-Dim, vs SAC+HER",
        FETCH_REACH_SOURCE,
        net_arch=[64, 64],
    ),
    # the same from the shipped Fetch-Push UDPO (256x256, this challenge's recipe)
    "high-dim-action-push": _from_shipped_source(
        CHALLENGES["high-dim-action-push"],
        "the shipped Fetch-Push UDPO's state planner, frozen, in a UDPO on Fetch-Push-High-Dim, vs SAC+HER",
        FETCH_PUSH_SOURCE,
        net_arch=[256, 256],
    ),
    # the challenge's evaluations of one training seed's models (the seed whose chosen checkpoint scored best on its
    # held-out open-arena episodes), on every evaluation seed
    "pointmaze-to-antmaze": Challenge(
        "pointmaze-to-antmaze-shipped",
        "the shipped PointMaze goal planner (SAC+HER teacher) guiding the shipped open-arena SAC Ant controller "
        "(AntMaze_Open-v5, its checkpoint chosen on held-out open-arena episodes) on AntMaze_UMaze-v5, far start to "
        "far goal (0 U-maze steps, no training stage), vs the same controller unguided",
        "AntMaze_UMaze-v5",
        (
            Shipped("distill", UMAZE_SHIPPED_DIR / "pointmaze_planner_seed0.pt"),
            Shipped("chosen", UMAZE_SHIPPED_DIR / "antmaze_open_controller_seed0_sac_300k.zip"),
            *_umaze_evaluations("chosen", controller_algo="sac"),
        ),
        steps={"smoke": {"pilot": 50, "unguided": 50, "open_ground": 50}},  # smoke: 50-step episodes
    ),
    # one source for every seed: the plain Maze2D planner shipped with Zero-shot Ant-Maze (UDPO on Maze2D, uniform starts
    # and goals, 20k steps, seed 0: this challenge's source recipe at seed 0)
    "maze-car": Challenge(
        "maze-car-shipped",
        MAZE_CAR_DESCRIPTION + "; one shipped Maze2D planner for every seed",
        "Pilot/Maze2DCar-v0",
        (Shipped("distill", MAZE_CAR_PLANNER), *MAZE_CAR_STAGES[2:]),
        steps={
            budget: {name: steps[name] for name in ("pilot", "pilot_disp", "her", "mega")}
            for budget, steps in MAZE_CAR_STEPS.items()
        },
        recipe="maze_car",
    ),
}


def only_stages(challenge: Challenge, names: list[str]) -> Challenge:
    """
    The challenge reduced to the stages ``names`` and, transitively, those they read from and those they are compared
    with (a guided controller's ``compared_with``).

    :param challenge: the challenge
    :param names: stage names
    :raise ValueError: for a name that is no stage of the challenge
    """
    stages = {stage.name: stage for stage in challenge.stages}
    unknown = sorted(set(names) - set(stages))
    if unknown:
        raise ValueError(f"--stages: {unknown} are not stages of {challenge.name} ({', '.join(stages)})")
    kept, todo = set(), list(names)
    while todo:
        name = todo.pop()
        if name not in kept:
            kept.add(name)
            todo.extend(stages[name].needs)
            stage = stages[name]
            if isinstance(stage, ControllerEvaluation) and stage.compared_with is not None:
                todo.append(stage.compared_with)
    return dataclasses.replace(challenge, stages=tuple(stage for stage in challenge.stages if stage.name in kept))
