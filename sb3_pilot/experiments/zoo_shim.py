"""
What this package changes in the RL Zoo where the zoo has no hook for it, in one place. Nothing here runs at import:
each change holds only while one of ``python -m sb3_pilot.experiments.zoo``'s commands runs, and is applied only
after :func:`check_rl_zoo3` has found the zoo's internals it relies on as they were read (in the rl_zoo3 versions
:data:`TESTED_RL_ZOO3_VERSIONS`; ``tests/test_zoo_shim.py`` fails on any other version, so that an upgrade is read
again before it is allowed). What goes through the zoo's public surface (``ALGOS``, samplers, tasks) is in
:mod:`sb3_pilot.experiments.zoo_plugin`.

- ``train`` builds :class:`PilotExperimentManager` in place of the zoo's ``ExperimentManager``
  (:func:`zoo_train_with`): the zoo's ``train()`` parses its command line and builds its manager by the name
  ``rl_zoo3.train.ExperimentManager``, with no parameter for another class.
- ``record_training`` runs the zoo's script, which records each model with ``subprocess.call(["python", "-m",
  "rl_zoo3.record_video", ...])``, a command that knows no ``udpo``: :func:`record_video_calls_to` sends those calls
  to this package's entry point.
"""

from __future__ import annotations

import inspect
import subprocess
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from importlib.util import find_spec
from pathlib import Path
from typing import Any

from rl_zoo3.exp_manager import ExperimentManager
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import CheckpointCallback, EvalCallback
from stable_baselines3.common.utils import get_latest_run_id

from sb3_pilot.common.checkpoint import CHECKPOINT_FILE, CheckpointEvery, RestoreCounters, load_checkpoint, read_checkpoint
from sb3_pilot.experiments.evaluation import GoalEvalCallback

#: The rl_zoo3 versions whose internals this module was checked against.
TESTED_RL_ZOO3_VERSIONS = ("2.9.2",)
#: The command the zoo's ``record_training`` records each model with, and its call in that script's source.
ZOO_RECORD_VIDEO = ("python", "-m", "rl_zoo3.record_video")
_ZOO_RECORD_VIDEO_CALL = 'subprocess.call(["python", "-m", "rl_zoo3.record_video"'


def _source(function: Callable[..., Any]) -> str:
    return inspect.getsource(function)


def _train_problems() -> list[str]:
    """What has changed, in the installed rl_zoo3, of what :class:`PilotExperimentManager` and :func:`zoo_train_with`
    rely on (empty: nothing)."""
    import rl_zoo3.exp_manager
    import rl_zoo3.train

    problems = []
    if getattr(rl_zoo3.train, "ExperimentManager", None) is not ExperimentManager or "ExperimentManager(" not in _source(
        rl_zoo3.train.train
    ):
        problems.append("rl_zoo3.train.train no longer builds rl_zoo3.exp_manager.ExperimentManager by that name")
    if "self._eval_env_kwargs_args = eval_env_kwargs" not in _source(ExperimentManager.__init__):
        problems.append("ExperimentManager.__init__ no longer keeps --eval-env-kwargs as self._eval_env_kwargs_args")
    if list(inspect.signature(ExperimentManager.read_hyperparameters).parameters) != ["self"]:
        problems.append("ExperimentManager.read_hyperparameters takes other arguments than self")
    if list(inspect.signature(ExperimentManager.create_callbacks).parameters) != ["self"]:
        problems.append("ExperimentManager.create_callbacks takes other arguments than self")
    for name in ("setup_experiment", "save_trained_model"):
        if name not in _source(rl_zoo3.train.train):
            problems.append(f"rl_zoo3.train.train no longer calls ExperimentManager.{name}")
    if 'self.params_path = f"{self.save_path}/{self.env_name}"' not in _source(ExperimentManager.__init__):
        problems.append("ExperimentManager.__init__ no longer derives params_path from save_path")
    for name, sb3_class in (("CheckpointCallback", CheckpointCallback), ("EvalCallback", EvalCallback)):
        if getattr(rl_zoo3.exp_manager, name, None) is not sb3_class or f"{name}(" not in _source(
            ExperimentManager.create_callbacks
        ):
            problems.append(f"ExperimentManager.create_callbacks no longer builds SB3's {name}")
    return problems


def _record_training_problems() -> list[str]:
    """What has changed, in the installed rl_zoo3, of what :func:`record_video_calls_to` relies on."""
    spec = find_spec("rl_zoo3.record_training")
    if spec is None or spec.origin is None or _ZOO_RECORD_VIDEO_CALL not in Path(spec.origin).read_text():
        return [f"rl_zoo3.record_training no longer records its models with {_ZOO_RECORD_VIDEO_CALL}, ...])"]
    return []


def check_rl_zoo3(parts: Sequence[str] = ("train", "record_training")) -> None:
    """
    Refuse an rl_zoo3 whose internals that this module's changes rely on have changed, naming them.

    :param parts: the changes to check: ``train`` (:func:`zoo_train_with`), ``record_training``
        (:func:`record_video_calls_to`)
    :raises RuntimeError: naming what changed and the versions this module was checked against
    """
    import rl_zoo3

    checks = {"train": _train_problems, "record_training": _record_training_problems}
    problems = [problem for part in parts for problem in checks[part]()]
    if problems:
        raise RuntimeError(
            f"sb3_pilot's changes to the RL Zoo (sb3_pilot.experiments.zoo_shim) were checked against rl_zoo3 "
            f"{', '.join(TESTED_RL_ZOO3_VERSIONS)}; in the installed rl_zoo3 {rl_zoo3.__version__}: "
            f"{'; '.join(problems)}. Install one of those versions, or adapt zoo_shim."
        )


class PilotExperimentManager(ExperimentManager):
    """
    The zoo's ``ExperimentManager`` (same arguments), which ``python -m sb3_pilot.experiments.zoo train`` builds, with
    three changes:

    - the evaluation is :class:`~sb3_pilot.experiments.evaluation.GoalEvalCallback` (``evaluations.npz`` also gets
      ``final_distances``), the zoo's ``EvalCallback`` otherwise unchanged;
    - the ``--save-freq`` checkpoints of a normalised run carry their ``VecNormalize`` statistics
      (``rl_model_vecnormalize_<steps>_steps.pkl`` beside ``rl_model_<steps>_steps.zip``): the zoo saves them with
      the final model only, so a checkpoint of a normalised run could not be evaluated;
    - the evaluation env gets the YAML entry's ``env_kwargs`` as the training env does: the zoo gives it the command
      line's ``--env-kwargs`` only, so a recipe whose task options are in its YAML (``cpu/ant_controller_upright.yml``:
      500-step episodes, moving goals) was evaluated on the default task. ``--eval-env-kwargs`` still wins.

    Made by :meth:`configured` (``train --checkpoint-freq N [--resume]``), it also keeps a resumable checkpoint of an
    off-policy run (:mod:`sb3_pilot.common.checkpoint`: model, optimizers, replay buffer with its frames compressed,
    random generators, the training's wall time so far) in ``<run folder>/checkpoint/``, every ``checkpoint_freq``
    env steps and when training ends or is interrupted (Ctrl-C, SIGINT); with ``resume``, it continues the latest run
    of the task in the log folder from its checkpoint, in that folder: same counters, its ``evaluations.npz`` going on
    from the checkpoint's step. A
    folder without a checkpoint, or a checkpoint of other settings (algorithm, task, seed, hyperparameters, env kwargs;
    ``n_timesteps`` aside, so that a resumed run may go further), is refused before training, naming the problem.
    """

    #: env steps between two checkpoints (0: none)
    checkpoint_freq: int = 0
    #: whether to continue the latest run from its checkpoint
    resume: bool = False
    #: the folder of the run's checkpoint, in its run folder
    CHECKPOINT_FOLDER = "checkpoint"

    @classmethod
    def configured(cls, checkpoint_freq: int = 0, resume: bool = False) -> type[PilotExperimentManager]:
        """
        :param checkpoint_freq: env steps between two checkpoints (0: none; then ``resume`` cannot be set)
        :param resume: continue the latest run from its checkpoint
        :return: the manager class that checkpoints (and resumes) so
        :raise ValueError: for a negative frequency, or ``resume`` without checkpoints
        """
        if checkpoint_freq < 0:
            raise ValueError(f"--checkpoint-freq must be >= 0 (0: no checkpoint), got {checkpoint_freq}.")
        if resume and not checkpoint_freq:
            raise ValueError("--resume continues a run from its checkpoints: give the --checkpoint-freq it was trained with.")
        return type(cls.__name__, (cls,), {"checkpoint_freq": checkpoint_freq, "resume": resume})

    def __init__(self, *args: Any, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self._checkpoint_settings: dict[str, Any] = {}
        if not self.resume:
            return
        if self.continue_training:
            raise SystemExit("--resume continues the latest run from its checkpoint; -i/--trained-agent starts another.")
        run_id = get_latest_run_id(self.log_path, self.env_name)
        folder = Path(self.log_path, f"{self.env_name}_{run_id}")
        if run_id == 0 or not (folder / self.CHECKPOINT_FOLDER / CHECKPOINT_FILE).is_file():
            where = f"{folder / self.CHECKPOINT_FOLDER}" if run_id else f"{self.log_path} (no run of {self.env_name})"
            raise SystemExit(
                f"--resume: no checkpoint in {where}; a run checkpoints with --checkpoint-freq N. Drop --resume to start "
                "a new run."
            )
        self.save_path = str(folder)
        self.params_path = f"{self.save_path}/{self.env_name}"

    @property
    def checkpoint_folder(self) -> Path:
        """Where the run's checkpoint is kept."""
        return Path(self.save_path, self.CHECKPOINT_FOLDER)

    def setup_experiment(self) -> tuple[BaseAlgorithm, dict[str, Any]] | None:
        results = super().setup_experiment()
        if results is None or not self.checkpoint_freq:
            return results
        model, saved_hyperparams = results
        self._checkpoint_settings = {
            "algo": self.algo,
            "env": self.env_name.gym_id,
            "seed": self.seed,
            "env_kwargs": self.env_kwargs,
            "hyperparams": {key: value for key, value in saved_hyperparams.items() if key != "n_timesteps"},
        }
        if self.resume:
            from rl_zoo3 import ALGOS

            try:
                model = load_checkpoint(
                    self.checkpoint_folder,
                    ALGOS[self.algo],
                    model.get_env(),  # type: ignore[arg-type]
                    self._checkpoint_settings,
                    device=self.device,
                    verbose=self.verbose,
                    tensorboard_log=self.tensorboard_log,
                )
            except (FileNotFoundError, ValueError) as error:
                raise SystemExit(f"--resume: {error}") from error
            print(f"Resuming {self.save_path} at {model.num_timesteps} env steps (of {self.n_timesteps})")
            for callback in self.callbacks:
                if isinstance(callback, GoalEvalCallback):
                    callback.restore_history(model.num_timesteps)
            self.callbacks.insert(0, RestoreCounters(model, self.callbacks))  # type: ignore[arg-type]
            training_s = read_checkpoint(self.checkpoint_folder).get("training_s")
        else:
            training_s = 0.0
        save_freq = max(self.checkpoint_freq // self.n_envs, 1)
        self._checkpointing = CheckpointEvery(save_freq, self.checkpoint_folder, self._checkpoint_settings, training_s)
        self.callbacks.append(self._checkpointing)
        return model, saved_hyperparams

    def save_trained_model(self, model: BaseAlgorithm) -> None:
        super().save_trained_model(model)
        if self.checkpoint_freq:  # the last checkpoint, at the end or where training was interrupted
            self._checkpointing.save()
            print(f"Checkpoint at {model.num_timesteps} env steps in {self.checkpoint_folder}")

    def read_hyperparameters(self) -> tuple[dict[str, Any], dict[str, Any]]:
        hyperparams, saved_hyperparams = super().read_hyperparameters()
        if self._eval_env_kwargs_args is None and "env_kwargs" in hyperparams:
            self.eval_env_kwargs = hyperparams["env_kwargs"]  # the training env's (ExperimentManager.env_kwargs)
        return hyperparams, saved_hyperparams

    def create_callbacks(self) -> None:
        ours = len(self.callbacks)  # those of the YAML's ``callback`` come first and stay as they are
        super().create_callbacks()
        made = [type(callback) for callback in self.callbacks[ours:]]
        for index in range(ours, len(self.callbacks)):
            callback = self.callbacks[index]
            if type(callback) is CheckpointCallback:
                callback.save_vecnormalize = True
            elif type(callback) is EvalCallback:
                self.callbacks[index] = GoalEvalCallback.from_eval_callback(callback)
        evaluates = self.eval_freq > 0 and not self.optimize_hyperparameters
        wanted = {CheckpointCallback: self.save_freq > 0, EvalCallback: evaluates}
        missing = [cls.__name__ for cls, want in wanted.items() if want and cls not in made]
        if missing:
            raise RuntimeError(
                f"The zoo's ExperimentManager.create_callbacks made no {' nor '.join(missing)} (rl_zoo3 changed): "
                "sb3_pilot.experiments.zoo_shim.PilotExperimentManager cannot change them."
            )


@contextmanager
def zoo_train_with(manager_class: type[ExperimentManager] = PilotExperimentManager) -> Iterator[None]:
    """
    While it holds, the zoo's ``rl_zoo3.train.train()`` builds ``manager_class`` in place of its ``ExperimentManager``.

    :param manager_class: a subclass of the zoo's ``ExperimentManager``
    :raises RuntimeError: from :func:`check_rl_zoo3`
    """
    import rl_zoo3.train

    check_rl_zoo3(["train"])
    zoo_class = rl_zoo3.train.ExperimentManager
    rl_zoo3.train.ExperimentManager = manager_class  # type: ignore[misc]
    try:
        yield
    finally:
        rl_zoo3.train.ExperimentManager = zoo_class  # type: ignore[misc]


@contextmanager
def record_video_calls_to(command: Sequence[str]) -> Iterator[None]:
    """
    While it holds, ``subprocess.call`` runs ``command`` in place of :data:`ZOO_RECORD_VIDEO` (the arguments after it
    kept), as the zoo's ``record_training`` script calls it; other calls are left as they are.

    :param command: e.g. ``[sys.executable, "-m", "sb3_pilot.experiments.zoo", "record_video"]``
    :raises RuntimeError: from :func:`check_rl_zoo3`
    """
    check_rl_zoo3(["record_training"])
    zoo_call = subprocess.call

    def call(args: Sequence[str], *rest: Any, **kwargs: Any) -> int:
        if tuple(args[: len(ZOO_RECORD_VIDEO)]) == ZOO_RECORD_VIDEO:
            args = [*command, *args[len(ZOO_RECORD_VIDEO) :]]
        return zoo_call(args, *rest, **kwargs)

    subprocess.call = call  # type: ignore[assignment]
    try:
        yield
    finally:
        subprocess.call = zoo_call
