"""
RL-Zoo entry point: ``python -m sb3_pilot.experiments.zoo COMMAND [zoo flags]``, COMMAND one of ``train``, ``enjoy``,
``record_video``, ``record_training``, ``plot_train``, ``plot_from_file``, ``all_plots``, and ``distill``, this
package's own (:func:`distill_zoo_run`: the goal planner of a trained zoo run, written where ``sac_pilot.yml``'s bonus
reads it).

:func:`register` adds UDPO to the zoo as ``udpo`` (``rl_zoo3.ALGOS``, plus a hyperparameter sampler for
``--optimize``) and :class:`~sb3_pilot.sac.LeanSAC` as ``lean_sac`` (SAC's YAML and sampler), and registers the
``Pilot/`` tasks; :func:`main` then runs the zoo's own command, as the RL-Zoo
docs do for SBX, so every zoo flag works. Five conveniences on top of ``python -m rl_zoo3.cli``:

- ``train`` without ``--conf-file`` reads this package's ``hyperparams/<algo>.yml`` for ``udpo`` and for any task
  that file has an entry for (every ``Pilot/`` task, gymnasium-robotics' ``FetchReach-v4``, ...), where the zoo
  would look inside the ``rl_zoo3`` package;
- a ``--conf-file`` that is no file from the current folder is looked up in that ``hyperparams/`` folder, so
  ``--conf-file cpu/udpo.yml`` or ``--conf-file sac_pilot.yml`` work from anywhere;
- the evaluation env gets a YAML entry's ``env_kwargs`` as the training env does (the zoo gives it those of the
  command line only), unless ``--eval-env-kwargs`` says otherwise;
- ``--save-freq`` checkpoints of a normalised run carry their ``VecNormalize`` statistics
  (:class:`NormalizedCheckpointCallback`), which the zoo saves with the final model only;
- ``plot_train -o FILE`` saves the figure (the zoo only calls ``plt.show()``), and ``-e Pilot/...`` finds the
  zoo's log folders (named ``Pilot-...``).

``record_video`` and ``record_training`` are the zoo's scripts (``rl_zoo3.record_video``, ``rl_zoo3.record_training``)
with UDPO and the tasks registered; ``record_training`` records each checkpoint through this entry point (the zoo's
calls ``python -m rl_zoo3.record_video``, which knows no ``udpo``) and runs the ``ffmpeg`` command (the system's, else
``imageio-ffmpeg``'s).
"""

from __future__ import annotations

import argparse
import functools
import os
import runpy
import shutil
import site
import subprocess
import sys
import sysconfig
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import gymnasium as gym
import optuna
import rl_zoo3
import yaml
from gymnasium.envs.registration import EnvSpec, load_env_creator
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import CheckpointCallback
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

from sb3_pilot.envs import register_envs
from sb3_pilot.experiments.evaluation import GoalEvalCallback
from sb3_pilot.sac import LeanSAC
from sb3_pilot.udpo import UDPO

#: Zoo algorithms of this package that read another algorithm's YAML (``--algo lean_sac`` reads ``sac.yml``).
CONF_OF = {"lean_sac": "sac"}
#: Commands of ``python -m rl_zoo3.cli`` that :func:`main` runs.
ZOO_COMMANDS = ("train", "enjoy", "record_video", "record_training", "plot_train", "plot_from_file", "all_plots")
#: The paper's UDPO search grid (appendix, "Important Hyperparameters"): ``lambda`` and ``Delta``.
PLANNER_COEF_GRID = (1e-3, 5e-3, 1e-2, 5e-2, 1e-1)
INVERSE_DYNAMICS_INTERVAL_GRID = (200, 500, 1500, 2000)


def hyperparams_dir() -> Path:
    """
    The package's RL-Zoo YAML folder: ``hyperparams/`` of the source checkout (editable install), else the copy a
    wheel installs under ``<prefix>/share/sb3_pilot/hyperparams`` (setup.cfg ``data_files``).
    """
    share = Path("share", "sb3_pilot", "hyperparams")
    candidates = [
        Path(__file__).resolve().parents[2] / "hyperparams",
        Path(sysconfig.get_path("data")) / share,
        Path(site.getuserbase()) / share,
    ]
    for candidate in candidates:
        if (candidate / "udpo.yml").is_file():
            return candidate
    raise FileNotFoundError(f"sb3_pilot's hyperparams/ folder was not found in {[str(path) for path in candidates]}.")


def sample_udpo_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict[str, Any]) -> dict[str, Any]:
    """``--optimize`` sampler for UDPO: the zoo's SAC sampler plus the paper's grid for ``lambda`` and ``Delta``."""
    from rl_zoo3.hyperparams_opt import sample_sac_params

    hyperparams = sample_sac_params(trial, n_actions, n_envs, additional_args)
    hyperparams["planner_coef"] = trial.suggest_categorical("planner_coef", PLANNER_COEF_GRID)
    hyperparams["inverse_dynamics_interval"] = trial.suggest_categorical(
        "inverse_dynamics_interval", INVERSE_DYNAMICS_INTERVAL_GRID
    )
    return hyperparams


def _eval_env_like_training(preprocess: Callable[..., Any]) -> Callable[..., Any]:
    """
    The zoo's ``ExperimentManager._preprocess_hyperparams``, after which the evaluation env gets the ``env_kwargs`` of
    the YAML entry, as the training env does. The zoo builds its evaluation env with the ``--env-kwargs`` of the
    command line only (``eval_env_kwargs`` is set before the YAML is read), so a recipe whose task options are in
    its YAML (``cpu/ant_controller_upright.yml``: 500-step episodes, moving goals) was evaluated on the default task.
    ``--eval-env-kwargs`` still wins.
    """

    @functools.wraps(preprocess)
    def wrapped(self: Any, hyperparams: dict[str, Any]) -> Any:
        result = preprocess(self, hyperparams)
        if self._eval_env_kwargs_args is None:
            self.eval_env_kwargs = self.env_kwargs
        return result

    return wrapped


class NormalizedCheckpointCallback(CheckpointCallback):
    """
    The zoo's ``--save-freq`` checkpoints, each with the ``VecNormalize`` statistics its model needs
    (``rl_model_vecnormalize_<steps>_steps.pkl`` beside ``rl_model_<steps>_steps.zip``) when training normalises: the
    zoo saves them with the final model only, so a checkpoint of a normalised run could not be evaluated.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, save_vecnormalize=True, **kwargs)


def register() -> None:
    """
    Register the ``Pilot/`` tasks and gymnasium-robotics' tasks (whose own IDs ``hyperparams/`` also covers), UDPO
    as the zoo's ``udpo`` (model class, ``--optimize`` sampler), and :class:`GoalEvalCallback` as the zoo's evaluation
    (``evaluations.npz`` gets ``final_distances``), and :class:`NormalizedCheckpointCallback` as its checkpoints.
    """
    import gymnasium_robotics
    from rl_zoo3 import ALGOS, exp_manager
    from rl_zoo3.hyperparams_opt import (
        HYPERPARAMS_CONVERTER,
        HYPERPARAMS_SAMPLER,
        convert_offpolicy_params,
        sample_sac_params,
    )

    register_envs()
    gym.register_envs(gymnasium_robotics)
    exp_manager.EvalCallback = GoalEvalCallback  # the zoo's evaluations also record the final distance to the goal
    exp_manager.CheckpointCallback = NormalizedCheckpointCallback
    if not hasattr(exp_manager.ExperimentManager._preprocess_hyperparams, "__wrapped__"):
        exp_manager.ExperimentManager._preprocess_hyperparams = _eval_env_like_training(
            exp_manager.ExperimentManager._preprocess_hyperparams
        )
    ALGOS["udpo"] = UDPO
    HYPERPARAMS_SAMPLER["udpo"] = sample_udpo_params
    HYPERPARAMS_CONVERTER["udpo"] = convert_offpolicy_params
    ALGOS["lean_sac"] = LeanSAC
    HYPERPARAMS_SAMPLER["lean_sac"] = sample_sac_params
    HYPERPARAMS_CONVERTER["lean_sac"] = convert_offpolicy_params


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
    zoo_call = subprocess.call

    def call(args: list[str], *rest: Any, **kwargs: Any) -> int:
        if list(args[:3]) == ["python", "-m", "rl_zoo3.record_video"]:
            args = [sys.executable, "-m", "sb3_pilot.experiments.zoo", "record_video", *args[3:]]
        return zoo_call(args, *rest, **kwargs)

    sys.argv = [prog, *zoo_argv]
    with _ffmpeg_command():
        subprocess.call = call  # type: ignore[assignment]
        try:
            runpy.run_module("rl_zoo3.record_training", run_name="__main__")
        finally:
            subprocess.call = zoo_call


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


def find_zoo_run(folder: str | os.PathLike, algo: str, env_id: str, exp_id: int = 0) -> Path:
    """
    The final model of a zoo run, found as ``enjoy`` finds it: ``<folder>/<algo>/<env name>_<exp_id>/<env name>.zip``.

    :param folder: the zoo's log folder (``-f``)
    :param algo: the zoo algorithm of the run
    :param env_id: its task
    :param exp_id: the run's number (0: the latest)
    :return: the model's path
    :raises FileNotFoundError: naming what is missing: any run of ``algo`` on ``env_id`` under ``folder`` (the runs that
        are there listed), the run ``exp_id``, the run's model
    """
    from huggingface_sb3 import EnvironmentName
    from rl_zoo3.utils import get_latest_run_id

    if exp_id < 0:
        raise ValueError(f"--exp-id must be a run number (>= 1) or 0 for the latest, got {exp_id}.")
    env_name = EnvironmentName(env_id)
    algo_dir = Path(folder) / algo
    latest = get_latest_run_id(str(algo_dir), env_name)
    if latest == 0:
        runs = sorted(f"{path.parent.name}/{path.name}" for path in Path(folder).glob("*/*_[0-9]*") if path.is_dir())
        raise FileNotFoundError(
            f"No run of {algo} on {env_id} under {folder} (no folder {algo_dir / env_name}_<N>); runs there: "
            f"{', '.join(runs) or 'none'}."
        )
    run_dir = algo_dir / f"{env_name}_{exp_id or latest}"
    if not run_dir.is_dir():
        ids = sorted(int(path.name.rsplit("_", 1)[1]) for path in algo_dir.glob(f"{env_name}_[0-9]*") if path.is_dir())
        raise FileNotFoundError(f"--exp-id {exp_id}: there is no run {run_dir}; the runs of {algo} on {env_id}: {ids}.")
    model_path = run_dir / f"{env_name}.zip"
    if not model_path.is_file():
        raise FileNotFoundError(
            f"The run {run_dir} has no model {model_path.name} (the zoo saves it when training ends: was it interrupted?)."
        )
    return model_path


def zoo_saved(model_path: Path, name: str) -> dict[str, Any]:
    """
    A settings file the zoo saved beside a model (``args.yml``: the command line; ``config.yml``: the YAML entry).

    :param model_path: ``<run folder>/<env name>.zip``
    :param name: the file's name
    :return: its entries, empty if the file is not there (a model saved without them)
    """
    path = model_path.parent / model_path.stem / name
    if not path.is_file():
        return {}
    # the zoo writes OrderedDicts (python tags), read back as its own enjoy script does
    return dict(yaml.load(path.read_text(), Loader=yaml.UnsafeLoader))


def load_zoo_run(
    model_path: str | os.PathLike, algo: str, env_id: str, seed: int = 0, device: str = "auto", buffer_size: int | None = 1
) -> tuple[BaseAlgorithm, VecEnv]:
    """
    The model of a zoo run, with its env rebuilt as the zoo's ``enjoy`` rebuilds it (``rl_zoo3.create_test_env``): the
    run's ``env_wrapper`` and ``normalize`` (its saved ``config.yml``), its ``env_kwargs`` (the YAML entry's, replaced by
    the command line's saved in ``args.yml``) and its ``VecNormalize`` statistics, frozen.

    :param model_path: ``<run folder>/<env name>.zip`` (:func:`find_zoo_run`)
    :param algo: the zoo algorithm that saved it (``sac``, ``td3``, ``tqc``, ``udpo``, ``lean_sac``, ...)
    :param env_id: its task
    :param seed: seed of the env
    :param device: the model's device
    :param buffer_size: the replay buffer's size (1: no room is allocated, for a model that acts only; None: the run's)
    :return: the model (its env attached) and the env
    """
    from rl_zoo3 import ALGOS
    from rl_zoo3.utils import create_test_env, get_saved_hyperparams

    model_path = Path(model_path)
    saved = model_path.parent / model_path.stem
    hyperparams, stats_path = get_saved_hyperparams(str(saved), norm_reward=False, test_mode=True)
    env_kwargs = dict(hyperparams.pop("env_kwargs", None) or {})
    command_line = zoo_saved(model_path, "args.yml").get("env_kwargs")
    if command_line is not None:  # the command line's --env-kwargs replaced the YAML's
        env_kwargs = dict(command_line)
    env = create_test_env(
        env_id,
        stats_path=stats_path,
        seed=seed,
        should_render=False,
        hyperparams=hyperparams,
        env_kwargs=env_kwargs,
        vec_env_cls=DummyVecEnv,
    )
    kwargs = {} if buffer_size is None else {"buffer_size": buffer_size}
    return ALGOS[algo].load(model_path, env=env, device=device, **kwargs), env


def planner_quality(metadata: dict[str, Any]) -> str:
    """
    What a goal planner's metadata says of its quality (:func:`~sb3_pilot.distill_goal_planner`'s held-out report), in
    one line: the held-out landmark distance (from the student's mean to the teacher's) beside the untrained student's
    and the teacher's own step, the held-out NLL, and the success of the teacher's rollouts (``labels="rollouts"``).

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
    model, env = load_zoo_run(model_path, args.algo, args.env, seed=args.seed, device=args.device, buffer_size=buffer_size)
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

        sys.argv = [prog, *_with_conf_file(zoo_argv)]
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
