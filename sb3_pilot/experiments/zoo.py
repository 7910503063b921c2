"""
RL-Zoo entry point: ``python -m sb3_pilot.experiments.zoo COMMAND [zoo flags]``, COMMAND one of ``train``, ``enjoy``,
``record_video``, ``record_training``, ``plot_train``, ``plot_from_file``, ``all_plots``.

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
from stable_baselines3.common.callbacks import CheckpointCallback

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


def main(argv: list[str] | None = None) -> None:
    """Run ``python -m sb3_pilot.experiments.zoo COMMAND [zoo flags]`` (``argv`` defaults to ``sys.argv[1:]``)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] not in ZOO_COMMANDS:
        commands = ",".join(ZOO_COMMANDS)
        raise SystemExit(f"usage: python -m sb3_pilot.experiments.zoo {{{commands}}} [RL-Zoo flags, see COMMAND -h]")
    command, zoo_argv = argv[0], argv[1:]
    prog = f"python -m sb3_pilot.experiments.zoo {command}"
    register()
    if command == "train":
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
