"""
Guide a trained goal-conditioned controller on a task with a goal planner's landmarks, zero-shot, and measure it beside
the same controller unguided: the recipe for a maze no page of these docs names.

    python -m sb3_pilot.experiments.guide --controller CONTROLLER.zip --planner PLANNER.pt --env AntMaze_Medium-v5 \\
        --goal-scale 4 [--env-kwargs continuing_task:False] [--lead 2.75] [--episodes 30] [--out guide.json]

Nothing is guessed by hand:

- the task options that decide what the controller sees and which body it moves (the Ant's ``xml_file``, the contact
  forces in its observation) come from the controller's zoo run (``args.yml``, ``config.yml`` beside it), and a task
  that asks for others, or gives other observations, is refused by name before any episode;
- a planner that learnt nothing beyond staying put (its distillation's held-out report) is refused, with the remedy;
- ``k`` is the horizon whose landmark lies about ``--lead`` ahead on the task's own start and goal pairs (default: 0.9
  of the farthest goal the controller trained on, where its run says it: 2.7 for the Ant recipe's goals 0.5-3 away);
  the switch to the real goal is within the task's success radius plus the planner's own offset from a goal it plans
  for (:func:`~sb3_pilot.transfer.choose_guidance`), so that a controller settled on the last landmark sees the goal.

It prints the choice and the two success rates (deterministic episodes, episode ``i`` of seed ``s`` reset with seed
``10_000 s + i``), and with ``--out`` writes them, every episode's final distance and the guided paths as JSON.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from sb3_pilot.distill import GoalMap, GoalPlanner, share_goal_space
from sb3_pilot.distill.distill import stay_put_message, stays_put
from sb3_pilot.experiments.challenges.controller import controller_episodes
from sb3_pilot.experiments.zoo_run import with_carried_env_kwargs, zoo_saved
from sb3_pilot.transfer import LandmarkGuidance, choose_guidance

#: The landmark's lead, as a share of the farthest goal the controller trained on (its recipe's ``goal_range``).
LEAD_SHARE = 0.9


def trained_goal_range(model_path: Path) -> tuple[float, float] | None:
    """
    The distances of the goals a controller trained on, where its zoo run says them: ``goal_range`` of its task
    options or of a wrapper of its YAML entry (:class:`~sb3_pilot.envs.controller_recipe.AntControllerRecipe`'s).

    :param model_path: the controller (a zoo run's model)
    :return: ``(low, high)``, or None where nothing says it
    """
    config = zoo_saved(model_path, "config.yml")
    env_kwargs = zoo_saved(model_path, "args.yml").get("env_kwargs") or config.get("env_kwargs") or {}
    wrappers = config.get("env_wrapper") or []
    options = [env_kwargs, *(kwargs for wrapper in wrappers if isinstance(wrapper, dict) for kwargs in wrapper.values())]
    found = next((option["goal_range"] for option in options if isinstance(option, dict) and "goal_range" in option), None)
    return None if found is None else (float(found[0]), float(found[1]))


def _parser() -> argparse.ArgumentParser:
    from rl_zoo3.utils import StoreDict

    parser = argparse.ArgumentParser(
        prog="python -m sb3_pilot.experiments.guide", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--controller", type=Path, required=True, help="the controller: a zoo run's model (.zip)")
    parser.add_argument("--planner", type=Path, required=True, help="the goal planner (.pt)")
    parser.add_argument("--env", required=True, help="the task to guide it on (a Gymnasium ID)")
    parser.add_argument(
        "--env-kwargs",
        nargs="+",
        action=StoreDict,
        default={},
        help="the task's options, as the zoo's (e.g. continuing_task:False)",
    )
    parser.add_argument(
        "--goal-scale",
        type=float,
        default=None,
        help="the task's goals are the planner's source task's times this (GoalMap; AntMaze_* from PointMaze_*: 4)",
    )
    parser.add_argument("--lead", type=float, default=None, help="the landmark's distance ahead (default: see above)")
    parser.add_argument("--max-horizon", type=int, default=100, help="the largest k considered")
    parser.add_argument("--success-radius", type=float, default=None, help="default: the task's")
    parser.add_argument("--switch-distance", type=float, default=None, help="default: chosen (see above)")
    parser.add_argument("--episodes", type=int, default=30, help="episodes of each (guided, unguided)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--algo", default=None, help="the controller's zoo algorithm (default: from its run)")
    parser.add_argument("--out", type=Path, default=None, help="write the results as JSON")
    return parser


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Choose the guidance, play the guided and the unguided episodes, print (and write) what they measured."""
    from sb3_pilot.experiments.zoo import register

    parser = _parser()
    args = parser.parse_args(argv)
    for path in (args.controller, args.planner):
        if not path.is_file():
            parser.error(f"{path} is no file")
    register()
    if args.env not in gym.registry:
        parser.error(f"--env {args.env} is no registered Gymnasium task (the Pilot/ and gymnasium-robotics' are)")
    planner = GoalPlanner.load(args.planner)
    if "holdout" in planner.metadata and stays_put(planner.metadata["holdout"]):
        parser.error(f"{args.planner}: {stay_put_message(planner.metadata['holdout'], planner.metadata.get('stride', 1))}")
    try:
        env_kwargs = with_carried_env_kwargs(args.controller, args.env, args.env_kwargs)
    except ValueError as error:
        parser.error(str(error))
    if args.goal_scale is not None:
        share_goal_space(str(planner.source_task), args.env, goal_map=GoalMap(args.goal_scale))
    lead = args.lead
    if lead is None:
        goal_range = trained_goal_range(args.controller)
        if goal_range is None:
            parser.error(f"nothing beside {args.controller} says how far its training goals were: give --lead")
        lead = LEAD_SHARE * goal_range[1]
    task = gym.make(args.env, **env_kwargs)
    try:
        settings = choose_guidance(task, planner, lead, radius=args.success_radius, max_horizon=args.max_horizon)
    except ValueError as error:  # a planner of another goal space, a task without success radius
        parser.error(str(error))
    switch = settings.switch_distance if args.switch_distance is None else args.switch_distance
    print(f"carried from the controller's run: {env_kwargs}")
    print(
        f"k = {settings.horizon} (landmark {settings.leads[settings.horizon - 1]:.2f} ahead, lead {lead:.2f}); switch to "
        f"the real goal within {switch:.2f} (success radius {settings.success_radius:.2f} + the planner's offset at a "
        f"goal {settings.goal_bias:.2f})",
        flush=True,
    )
    guided = LandmarkGuidance(task, planner, horizon=settings.horizon, switch_distance=switch)
    results: dict[str, Any] = {}
    for name, env in (("guided", guided), ("unguided", gym.make(args.env, **env_kwargs))):
        results[name] = controller_episodes(args.controller, env, args.episodes, args.seed, args.algo)
        env.close()
        print(
            f"{name}: success {np.mean(results[name]['successes']):.2f}, mean final distance "
            f"{np.mean(results[name]['final_distances']):.2f} ({args.episodes} episodes)",
            flush=True,
        )
    summary = {
        "env_id": args.env,
        "env_kwargs": env_kwargs,
        "controller": str(args.controller),
        "planner": str(args.planner),
        "lead": lead,
        "horizon": settings.horizon,
        "switch_distance": switch,
        "goal_bias": settings.goal_bias,
        "success_radius": settings.success_radius,
        "seed": args.seed,
        **{f"{name}_success": float(np.mean(result["successes"])) for name, result in results.items()},
        "results": results,
    }
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(summary, default=str))
    return summary


if __name__ == "__main__":
    main()
