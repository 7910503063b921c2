"""
RL-Zoo entry point: ``python -m sb3_pilot.experiments.zoo COMMAND [zoo flags]``, COMMAND one of ``train``, ``enjoy``,
``record_video``, ``record_training``, ``plot_train``, ``plot_from_file``, ``all_plots``, and ``distill``, this
package's own (the goal planner of a trained zoo run, written where ``sac_pilot.yml``'s bonus reads it).

:func:`main` calls :func:`~sb3_pilot.experiments.zoo_plugin.register` (UDPO as the zoo's ``udpo``,
:class:`~sb3_pilot.sac.LeanSAC` as ``lean_sac``, their ``--optimize`` samplers, the ``Pilot/`` and gymnasium-robotics'
tasks), then runs the zoo's own command, as the RL-Zoo docs do for SBX, so every zoo flag works. Six conveniences on
top of ``python -m rl_zoo3.cli``:

- ``train`` without ``--conf-file`` reads this package's ``hyperparams/<algo>.yml`` for ``udpo`` and for any task
  that file has an entry for (every ``Pilot/`` task, gymnasium-robotics' ``FetchReach-v4``, ...), where the zoo
  would look inside the ``rl_zoo3`` package;
- a ``--conf-file`` that is no file from the current folder is looked up in that ``hyperparams/`` folder, so
  ``--conf-file cpu/udpo.yml`` or ``--conf-file sac_pilot.yml`` work from anywhere;
- ``train`` evaluates with :class:`~sb3_pilot.experiments.evaluation.GoalEvalCallback` (``evaluations.npz`` gets the
  final distances to the goal), gives the evaluation env a YAML entry's ``env_kwargs`` as the training env gets
  them (the zoo gives it those of the command line only) unless ``--eval-env-kwargs`` says otherwise, and its
  ``--save-freq`` checkpoints of a normalised run carry their ``VecNormalize`` statistics, which the zoo saves with
  the final model only (:class:`~sb3_pilot.experiments.zoo_shim.PilotExperimentManager`);
- ``plot_train -o FILE`` saves the figure (the zoo only calls ``plt.show()``), and ``-e Pilot/...`` finds the
  zoo's log folders (named ``Pilot-...``);
- ``train --checkpoint-freq N`` keeps a resumable checkpoint of an off-policy run (model, optimizers, replay buffer
  with its frames compressed) every ``N`` env steps and when training ends or is interrupted, and ``train ...
  --checkpoint-freq N --resume`` (the same command otherwise, ``-n`` aside) continues the latest run of the task in
  the log folder from it (:class:`~sb3_pilot.experiments.zoo_shim.PilotExperimentManager`,
  :mod:`sb3_pilot.common.checkpoint`).

``record_video`` and ``record_training`` are the zoo's scripts (``rl_zoo3.record_video``, ``rl_zoo3.record_training``)
with UDPO and the tasks registered; ``record_training`` records each checkpoint through this entry point (the zoo's
calls ``python -m rl_zoo3.record_video``, which knows no ``udpo``) and runs the ``ffmpeg`` command (the system's, else
``imageio-ffmpeg``'s). The changes to the zoo that have no hook are in :mod:`sb3_pilot.experiments.zoo_shim`; reading
a zoo run back (``distill``'s teacher) is :mod:`sb3_pilot.experiments.zoo_run`.
"""

from __future__ import annotations

import argparse
import math
import os
import runpy
import shutil
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import gymnasium as gym
import rl_zoo3
import yaml
from gymnasium.envs.registration import EnvSpec, load_env_creator

from sb3_pilot.experiments.zoo_plugin import CONF_OF, hyperparams_dir, register
from sb3_pilot.experiments.zoo_run import find_zoo_run, load_zoo_run
from sb3_pilot.experiments.zoo_shim import PilotExperimentManager, record_video_calls_to, zoo_train_with

#: Commands of ``python -m rl_zoo3.cli`` that :func:`main` runs.
ZOO_COMMANDS = ("train", "enjoy", "record_video", "record_training", "plot_train", "plot_from_file", "all_plots")


def _with_conf_file(argv: list[str]) -> list[str]:
    """``train`` arguments with ``--conf-file`` defaulted or resolved in :func:`hyperparams_dir` (see module doc)."""
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--algo", default="ppo")
    parser.add_argument("--env", default="")
    parser.add_argument("-conf", "--conf-file", default=None)
    args, _ = parser.parse_known_args(argv)
    if args.conf_file is None:
        conf_name = CONF_OF.get(args.algo, args.algo)
        default = hyperparams_dir() / f"{conf_name}.yml"
        if default.is_file() and (args.algo == "udpo" or args.env in yaml.safe_load(default.read_text())):
            return [*argv, "--conf-file", str(default)]
        if args.algo in CONF_OF:  # the zoo's own file of that algorithm
            return [*argv, "--conf-file", str(Path(rl_zoo3.__file__).parent / "hyperparams" / f"{conf_name}.yml")]
    elif not Path(args.conf_file).exists() and (hyperparams_dir() / args.conf_file).is_file():
        return [*argv, "--conf-file", str(hyperparams_dir() / args.conf_file)]
    return argv


def _plot_train(argv: list[str], prog: str) -> None:
    """The zoo's ``plot_train``, with ``-o/--output`` (save the figure) and ``Pilot/`` env IDs."""
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("-o", "--output", default=None)
    args, zoo_argv = parser.parse_known_args(argv)
    if args.output is not None:
        import matplotlib

        matplotlib.use("Agg")  # the zoo's plt.show() does nothing and the figure stays open to be saved
    from matplotlib import pyplot as plt
    from rl_zoo3.plots import plot_train

    sys.argv = [prog, *(arg.replace("/", "-") if arg in gym.registry else arg for arg in zoo_argv)]
    plot_train()
    if args.output is not None:
        plt.savefig(args.output)
        print(f"Saved {args.output}")


def _renders(spec: EnvSpec) -> bool:
    """Whether a registered task renders ``rgb_array`` frames (as its class's ``metadata`` says; True if unknown)."""
    creator = load_env_creator(spec.entry_point) if isinstance(spec.entry_point, str) else spec.entry_point
    metadata = getattr(creator, "metadata", None)
    return not isinstance(metadata, dict) or "rgb_array" in metadata.get("render_modes", [])


def _check_renders(argv: list[str]) -> None:
    """Refuse, before loading anything, a ``record_video`` of a task that cannot render ``rgb_array`` frames."""
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--env", default="CartPole-v1")
    env_id = parser.parse_known_args(argv)[0].env
    if env_id in gym.registry and not _renders(gym.spec(env_id)):
        renders = [name for name, spec in gym.registry.items() if name.startswith("Pilot/") and _renders(spec)]
        raise SystemExit(
            f"record_video needs a task that renders rgb_array frames, {env_id} does not. "
            f"Pilot/ tasks that do: {', '.join(renders)}."
        )


@contextmanager
def _ffmpeg_command() -> Iterator[None]:
    """
    An ``ffmpeg`` command on ``PATH`` for the zoo's ``os.system("ffmpeg ...")`` calls: the system's, else the binary
    of ``imageio-ffmpeg`` (installed with the zoo, through ``moviepy``, which its videos need).
    """
    if shutil.which("ffmpeg") is not None:
        yield
        return
    try:
        import imageio_ffmpeg

        binary = imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError) as error:
        raise SystemExit(
            "record_training adds titles to the videos and joins them with the ffmpeg command, which is not on PATH "
            "(nor is imageio-ffmpeg's): install ffmpeg (e.g. apt install ffmpeg), or record one model with record_video."
        ) from error
    path = os.environ.get("PATH", "")
    with tempfile.TemporaryDirectory() as folder:
        os.symlink(binary, Path(folder, "ffmpeg"))
        os.environ["PATH"] = f"{folder}{os.pathsep}{path}"
        try:
            yield
        finally:
            os.environ["PATH"] = path


def _record_training(argv: list[str], prog: str) -> None:
    """
    The zoo's ``record_training``, whose ``python -m rl_zoo3.record_video`` calls (one per saved model) go to this
    entry point's ``record_video`` instead, with this Python. ``-o/--output-folder`` is made absolute: the zoo lists
    the videos for ``ffmpeg``'s concatenation by that path, which ``ffmpeg`` reads relative to the list's folder.
    """
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("-o", "--output-folder", default=None)
    args, zoo_argv = parser.parse_known_args(argv)
    if args.output_folder is not None:
        zoo_argv = [*zoo_argv, "--output-folder", str(Path(args.output_folder).resolve())]
    sys.argv = [prog, *zoo_argv]
    with _ffmpeg_command(), record_video_calls_to([sys.executable, "-m", "sb3_pilot.experiments.zoo", "record_video"]):
        runpy.run_module("rl_zoo3.record_training", run_name="__main__")


#: Where ``distill`` writes a planner unless told otherwise, under the zoo's log folder (``-f``):
#: ``<folder>/planners/<env name>.pt``, the path the bonus entries of ``hyperparams/sac_pilot.yml`` read with ``-f logs``
#: (e.g. ``logs/planners/Pilot-Maze2D-v0.pt``).
PLANNERS_FOLDER = "planners"
#: Arguments of :func:`~sb3_pilot.distill_goal_planner` that ``distill`` sets itself (not through ``--distill-kwargs``).
_DISTILL_SET = (
    *("model", "env", "source_task", "n_samples", "gradient_steps", "labels", "seed", "verbose"),
    "allow_unsuccessful_teacher",
)


def planner_path(folder: str | os.PathLike, env_id: str) -> Path:
    """
    :param folder: the zoo's log folder (``-f``)
    :param env_id: the teacher's task
    :return: where ``distill`` writes the planner of a teacher on ``env_id`` by default (:data:`PLANNERS_FOLDER`)
    """
    from huggingface_sb3 import EnvironmentName

    return Path(folder) / PLANNERS_FOLDER / f"{EnvironmentName(env_id)}.pt"


def planner_quality(metadata: dict[str, Any]) -> str:
    """
    What a goal planner's metadata says of its quality (:func:`~sb3_pilot.distill_goal_planner`'s held-out report), in
    one line: the held-out landmark distance (from the student's mean to the teacher's) beside the untrained student's
    and the teacher's own step, the held-out NLL, and the success of the teacher's rollouts (``labels="rollouts"``: of
    their ended episodes, and how many of their steps were at a goal).

    :param metadata: ``planner.metadata``
    """
    holdout = metadata.get("holdout", {})
    parts = []
    if "landmark_distance" in holdout:
        parts.append(
            f"held-out landmark distance {holdout['landmark_distance']:.3g} (untrained "
            f"{holdout.get('landmark_distance_untrained', float('nan')):.3g}; the teacher's mean step "
            f"{holdout.get('teacher_step', float('nan')):.3g})"
        )
    if "nll" in holdout:
        parts.append(f"held-out NLL {holdout['nll']:.3g} (untrained {holdout.get('nll_untrained', float('nan')):.3g})")
    if "rollout_success" in metadata:
        parts.append(f"the teacher's rollout success {metadata['rollout_success']:.2f}")
    goal_steps = metadata.get("rollout_goal_steps")
    if goal_steps is not None and not math.isnan(goal_steps):  # NaN: the task reports no success
        parts.append(f"{goal_steps:.0f} rollout steps at a goal")
    return "; ".join(parts) or "no held-out report in the metadata"


def _distill_parser(prog: str) -> argparse.ArgumentParser:
    from rl_zoo3 import ALGOS
    from rl_zoo3.utils import StoreDict

    from sb3_pilot.distill.teacher import LABELS

    parser = argparse.ArgumentParser(
        prog=prog,
        description="Distil the goal planner of a trained zoo run (any off-policy goal agent: sac, td3, tqc, udpo, ...) "
        "and write it where the bonus of hyperparams/sac_pilot.yml reads it.",
    )
    parser.add_argument("--algo", required=True, choices=sorted(ALGOS), help="the teacher's zoo algorithm")
    parser.add_argument("--env", required=True, help="the teacher's task (Gymnasium ID)")
    parser.add_argument("-f", "--folder", default="logs", help="the zoo's log folder (default: logs)")
    parser.add_argument("--exp-id", type=int, default=0, help="the run's number (default: 0, the latest)")
    parser.add_argument("--n-samples", type=int, default=50_000, help="pairs (env steps of the teacher's rollouts)")
    parser.add_argument("--gradient-steps", type=int, default=5_000)
    parser.add_argument(
        "--labels",
        default="rollouts",
        choices=LABELS,
        help="rollouts (any agent's own steps) or planned (UDPO's plans, read from its saved replay buffer)",
    )
    parser.add_argument(
        "--allow-unsuccessful-teacher", action="store_true", help="distil a teacher whose rollouts reach no goal"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help=f"the planner's file (default: FOLDER/{PLANNERS_FOLDER}/<env name>.pt)")
    parser.add_argument("--device", default="auto")
    parser.add_argument("--num-threads", type=int, default=-1, help="torch threads (-1: torch's default)")
    parser.add_argument("--verbose", type=int, default=0, choices=(0, 1))
    parser.add_argument(
        "--env-kwargs",
        nargs="+",
        action=StoreDict,
        default={},
        help="options of the task the rollouts run in, over the run's own (e.g. reset_target:True: a PointMaze goal "
        "that moves on once reached)",
    )
    parser.add_argument(
        "--distill-kwargs",
        nargs="+",
        action=StoreDict,
        default={},
        help="other distill_goal_planner arguments, as the zoo's -params (e.g. net_arch:[64,64] support_size:0)",
    )
    return parser


def _distill(argv: list[str], prog: str) -> None:
    """``distill``: :func:`find_zoo_run`, :func:`load_zoo_run`, :func:`~sb3_pilot.distill_goal_planner`, save, report."""
    import inspect

    import torch as th

    from sb3_pilot.distill import distill_goal_planner

    args = _distill_parser(prog).parse_args(argv)
    if args.env not in gym.registry:
        raise SystemExit(f"--env {args.env} is no registered Gymnasium task (the Pilot/ and gymnasium-robotics' are).")
    allowed = set(inspect.signature(distill_goal_planner).parameters) - set(_DISTILL_SET)
    unknown = sorted(set(args.distill_kwargs) - allowed)
    if unknown:
        raise SystemExit(f"--distill-kwargs: {unknown} are no arguments of distill_goal_planner here ({sorted(allowed)}).")
    try:
        model_path = find_zoo_run(args.folder, args.algo, args.env, args.exp_id)
    except (FileNotFoundError, ValueError) as error:
        raise SystemExit(str(error)) from error
    if args.labels != "rollouts" and not (model_path.parent / "replay_buffer.pkl").is_file():
        raise SystemExit(
            f"--labels {args.labels} reads the teacher's replay buffer, which the run {model_path.parent} did not save "
            "(train it with --save-replay-buffer), or distil with --labels rollouts."
        )
    out = Path(args.out) if args.out is not None else planner_path(args.folder, args.env)
    if args.num_threads > 0:
        th.set_num_threads(args.num_threads)
    print(f"Teacher: {model_path} ({args.algo})")
    buffer_size = 1 if args.labels == "rollouts" else None
    options = {"seed": args.seed, "device": args.device, "buffer_size": buffer_size, "env_kwargs": args.env_kwargs}
    model, env = load_zoo_run(model_path, args.algo, args.env, **options)
    if args.labels != "rollouts":
        model.load_replay_buffer(model_path.parent / "replay_buffer.pkl")
    try:
        planner = distill_goal_planner(
            model,
            n_samples=args.n_samples,
            gradient_steps=args.gradient_steps,
            labels=args.labels,
            seed=args.seed,
            env=env,
            source_task=args.env,
            verbose=args.verbose,
            allow_unsuccessful_teacher=args.allow_unsuccessful_teacher,
            **args.distill_kwargs,
        )
    except ValueError as error:  # a refused teacher or argument, named by distill_goal_planner
        message = str(error).replace("allow_unsuccessful_teacher=True", "--allow-unsuccessful-teacher")
        raise SystemExit(f"distill: {message}") from error
    finally:
        env.close()
    planner.metadata["teacher_model"] = str(model_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    planner.save(out)
    print(f"Saved the goal planner to {out}")
    print(f"Quality: {planner_quality(planner.metadata)}")


def _checkpointing_manager(argv: list[str]) -> type[PilotExperimentManager]:
    """
    The manager of ``train``, with this entry's ``--checkpoint-freq N`` and ``--resume`` (taken out of ``argv``, in
    place: the zoo's parser knows neither).

    :raise SystemExit: for a negative frequency, or ``--resume`` without one
    """
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--checkpoint-freq", type=int, default=0)
    parser.add_argument("--resume", action="store_true")
    args, rest = parser.parse_known_args(argv)
    argv[:] = rest
    try:
        return PilotExperimentManager.configured(args.checkpoint_freq, args.resume)
    except ValueError as error:
        raise SystemExit(str(error)) from error


def main(argv: list[str] | None = None) -> None:
    """Run ``python -m sb3_pilot.experiments.zoo COMMAND [zoo flags]`` (``argv`` defaults to ``sys.argv[1:]``)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] not in (*ZOO_COMMANDS, "distill"):
        commands = ",".join((*ZOO_COMMANDS, "distill"))
        raise SystemExit(f"usage: python -m sb3_pilot.experiments.zoo {{{commands}}} [RL-Zoo flags, see COMMAND -h]")
    command, zoo_argv = argv[0], argv[1:]
    prog = f"python -m sb3_pilot.experiments.zoo {command}"
    register()
    if command == "distill":
        _distill(zoo_argv, prog)
    elif command == "train":
        from rl_zoo3.train import train

        manager = _checkpointing_manager(zoo_argv)
        sys.argv = [prog, *_with_conf_file(zoo_argv)]
        with zoo_train_with(manager):  # the zoo's train, building sb3_pilot's ExperimentManager (see zoo_shim)
            train()
    elif command == "enjoy":
        from rl_zoo3.enjoy import enjoy

        sys.argv = [prog, *zoo_argv]
        enjoy()
    elif command == "record_video":  # a script, without a function to call
        _check_renders(zoo_argv)
        sys.argv = [prog, *zoo_argv]
        runpy.run_module("rl_zoo3.record_video", run_name="__main__")
    elif command == "record_training":
        _record_training(zoo_argv, prog)
    elif command == "plot_train":
        _plot_train(zoo_argv, prog)
    else:
        from rl_zoo3 import plots

        sys.argv = [prog, *zoo_argv]
        getattr(plots, command)()


if __name__ == "__main__":
    main()
