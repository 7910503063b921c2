"""
The stages of a transfer challenge, their configuration hash and the marker of a finished stage.

A challenge is a list of stages run once per seed: :class:`ZooTrain` (a ``python -m sb3_pilot.experiments.zoo train`` run),
:class:`Distill` (:func:`~sb3_pilot.distill_goal_planner` on a trained teacher); :class:`Shipped` stands for a file
that comes with the repository (a trained controller or planner) in place of a training stage. The stages of a trained
controller (its checkpoint's choice, its evaluation guided or not) are in
:mod:`sb3_pilot.experiments.challenges.controller`.
Each stage writes into its own folder ``<root>/<challenge>/models/seed_<k>/<stage>/`` (``models/`` is gitignored)
and, when it has finished, a marker ``stage.json`` holding the hash of its configuration (its settings and preset,
its budget and the hashes of the stages it reads from). A stage whose marker matches is skipped on the next run; one without
(interrupted) or with another hash is removed and run again, but a zoo stage that keeps resumable checkpoints
(:attr:`ZooTrain.checkpoint_freq`): stopped with one in its folder under the same hash, it continues from it (the zoo's
``--resume``). Each stage runs in a process of its own whose output goes to ``stage.log`` in its folder, a zoo stage's
whole command line to ``command.txt`` beside it (:mod:`sb3_pilot.experiments.challenges.backends`).
"""

from __future__ import annotations

import copy
import functools
import hashlib
import json
import shlex
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from sb3_pilot.common.checkpoint import CHECKPOINT_FILE
from sb3_pilot.common.utils import check_number
from sb3_pilot.distill import distill_goal_planner
from sb3_pilot.experiments.evaluation import load_final_distances
from sb3_pilot.experiments.zoo import hyperparams_dir, register

# the zoo-run readers that were defined here, for the modules that import them from here
from sb3_pilot.experiments.zoo_run import (  # noqa: F401
    load_zoo_model,
    training_task,
    vecnormalize_path,
    zoo_env_id,
    zoo_env_kwargs,
)
from sb3_pilot.experiments.zoo_shim import PilotExperimentManager

#: Marker a finished stage leaves in its folder.
STAGE_MARKER = "stage.json"
#: The stage process's stdout and stderr, in its folder.
STAGE_LOG = "stage.log"
#: A zoo stage's command line, in its folder.
STAGE_COMMAND = "command.txt"
#: What a zoo stage with resumable checkpoints writes in its folder when it starts: its configuration hash, so that a
#: later run continues it only under the same configuration (:attr:`ZooTrain.checkpoint_freq`).
STAGE_STARTED = "started.json"
#: What SB3's logger writes in a zoo stage's folder while it trains (:class:`CSVLogger`), env steps included.
PROGRESS_CSV = "progress.csv"
#: Hyperparameters of a zoo stage computed from the outputs of earlier stages (``{stage name: path}``).
Params = Callable[[dict[str, Path]], dict[str, Any]]


@dataclass(frozen=True)
class Import:
    """
    A class or function in a stage's ``-params`` (e.g. a ``features_extractor_class`` of ``policy_kwargs``), written on
    the zoo's command line as the expression that imports it (the zoo evaluates ``-params`` values).

    :param module: the module that defines it
    :param name: its name in the module
    """

    module: str
    name: str

    def __repr__(self) -> str:
        return f"__import__({self.module!r}, fromlist=[{self.name!r}]).{self.name}"


def zoo_value(value: Any) -> Any:
    """
    A YAML entry's value as the zoo reads it: a ``policy_kwargs`` string such as ``"dict(net_arch=[64, 64])"``
    evaluated (RL Zoo evaluates these strings), anything else as it is.
    """
    return eval(value) if isinstance(value, str) else value  # the zoo's own rule for these keys


def zoo_text(value: Any) -> str:
    """
    A ``-params`` value as Python text the zoo evaluates back to ``value``: its ``repr``, but classes and functions
    written as the expression that imports them (:class:`Import`).
    """
    if isinstance(value, dict):
        return "{" + ", ".join(f"{key!r}: {zoo_text(item)}" for key, item in value.items()) + "}"
    if isinstance(value, list | tuple):
        items = ", ".join(zoo_text(item) for item in value)
        return f"[{items}]" if isinstance(value, list) else f"({items}{',' * (len(value) == 1)})"
    if isinstance(value, type) or callable(value):
        return repr(Import(value.__module__, value.__qualname__))
    return repr(value)


#: The keys of a YAML entry whose string values RL Zoo evaluates as Python (``"dict(net_arch=[64, 64])"``).
EVALUATED_KEYS = ("policy_kwargs", "replay_buffer_kwargs", "monitor_kwargs", "normalize")


def zoo_hyperparams(config: dict[str, Any]) -> dict[str, Any]:
    """
    The hyperparameters a zoo stage trains with, as RL Zoo merges them: its YAML entry (``preset``) with the command
    line's ``-params`` over it key by key, the strings it evaluates (:data:`EVALUATED_KEYS`) evaluated.

    :param config: a :class:`ZooTrain` stage's configuration (:meth:`ZooTrain.config`: ``zoo`` and ``preset``)
    """
    args = config["zoo"]
    start = end = args.index("-params") + 1
    while end < len(args) and not args[end].startswith("--"):
        end += 1
    hyperparams = dict(config["preset"])
    for item in args[start:end]:
        key, _, value = item.partition(":")
        hyperparams[key] = eval(value)  # as the zoo's StoreDict reads -params
    return {key: zoo_value(value) if key in EVALUATED_KEYS else value for key, value in hyperparams.items()}


@dataclass(frozen=True)
class Budget:
    """
    How much a challenge run may spend, shared by the four challenges (their step counts are their own).

    :param name: ``smoke``, ``cpu``, ``paper`` or a custom name
    :param conf_dir: folder of ``hyperparams/`` the zoo stages read (``"cpu/"`` for the CPU presets, ``""``)
    :param n_evals: evaluations per training run (the zoo's ``--eval-freq`` is ``steps // n_evals``)
    :param eval_episodes: episodes per evaluation (the zoo's ``--eval-episodes``) and of a guidance stage
    :param distill: keyword arguments of :func:`~sb3_pilot.distill_goal_planner`
    :param hyperparams: overrides of every zoo stage's YAML entry (``-params``), e.g. small networks for ``smoke``
    :param recipes: read each challenge's recipe (its ``recipe`` folder under ``conf_dir``: the settings measured to
        learn quickly on this machine) instead of the plain ``conf_dir`` files
    """

    name: str
    conf_dir: str
    n_evals: int
    eval_episodes: int
    distill: dict[str, Any]
    hyperparams: dict[str, Any] = field(default_factory=dict)
    recipes: bool = True


@dataclass
class StageContext:
    """
    What a stage needs to run: where, for which seed, at which budget, and the outputs of earlier stages.

    :param seed_dir: ``<root>/<challenge>/models/seed_<k>``
    :param seed: the random seed
    :param budget: the budget
    :param steps: env steps of each stage at this budget (None: the YAML's ``n_timesteps``)
    :param recipe: the challenge's recipe folder if the budget reads recipes, else None (:meth:`ZooTrain.conf_file_at`)
    :param outputs: main output file of each finished stage (model zip, planner file, result file)
    :param verbose: verbosity of the zoo and of SB3 (0 or 1)
    :param threads: torch (and OpenMP) threads of the stage's process
    """

    seed_dir: Path
    seed: int
    budget: Budget
    steps: dict[str, int | None]
    recipe: str | None = None
    outputs: dict[str, Path] = field(default_factory=dict)
    verbose: int = 0
    threads: int = 1


class CSVLogger(BaseCallback):
    """
    Zoo callback: SB3's logger writes :data:`PROGRESS_CSV` in ``folder`` (the zoo itself only logs to stdout and
    TensorBoard), so that UDPO's ``rollout/plan_error`` can be plotted over training and the runner can show the env
    steps done.

    :param folder: where :data:`PROGRESS_CSV` goes
    :param verbose: verbosity level
    """

    def __init__(self, folder: str, verbose: int = 0):
        super().__init__(verbose)
        self.folder = folder

    def _init_callback(self) -> None:
        formats = ["csv", "stdout"] if self.model.verbose >= 1 else ["csv"]
        self.model.set_logger(configure(self.folder, formats))

    def _on_step(self) -> bool:
        return True


def zoo_run_dir(stage_dir: Path, algo: str, env_id: str) -> Path:
    """Folder where the zoo saves the first run of ``algo`` on ``env_id`` with ``-f stage_dir``."""
    return stage_dir / algo / f"{env_id.replace('/', '-')}_1"


def play_episodes(
    model: BaseAlgorithm, vec_normalize: VecNormalize | None, env: gym.Env, episodes: int, seed: int
) -> Iterator[tuple[dict[str, np.ndarray], dict[str, Any]]]:
    """
    Deterministic episodes of ``model`` on ``env``, episode ``i`` reset with seed ``10_000 * seed + i``.

    :param model: the trained model
    :param vec_normalize: its frozen ``VecNormalize`` (observations are normalised for it), or None
    :param env: the env (raw observations)
    :param episodes: number of episodes
    :param seed: seed of the evaluation
    :return: for each episode, once it has ended, its last observation and info
    """
    for episode in range(episodes):
        observation, _ = env.reset(seed=10_000 * seed + episode)
        done, info = False, {}
        while not done:
            seen = vec_normalize.normalize_obs(observation) if vec_normalize is not None else observation
            action, _ = model.predict(seen, deterministic=True)
            observation, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        yield observation, info


@functools.lru_cache(maxsize=32)
def _yaml_entries(path: Path, modified_ns: int) -> dict[str, Any]:
    """A YAML file's entries, read once per version of the file (a run plans hundreds of stages from a few files)."""
    return yaml.safe_load(path.read_text())


@dataclass(frozen=True)
class ZooTrain:
    """
    A training run of the zoo: ``python -m sb3_pilot.experiments.zoo train --algo ALGO --env ENV --conf-file BUDGET/CONF ...``.

    :param name: stage name (folder name, key of its output)
    :param algo: zoo algorithm (``udpo``, ``sac``)
    :param env_id: task
    :param conf_file: YAML in ``hyperparams/`` (:meth:`conf_file_at`: the budget's ``conf_dir`` and the challenge's
        recipe folder, where it has this file, are prepended; or the stage's own ``conf_dir``)
    :param params: ``-params`` computed from earlier stages' outputs (planner paths, transfer callbacks)
    :param needs: stages whose outputs ``params`` reads
    :param method: label in the summary if this stage is a compared method on the target task
    :param save_replay_buffer: keep the replay buffer (a later :class:`Distill` reads it)
    :param env_kwargs: keyword arguments of the task (the zoo's ``--env-kwargs``), for training and evaluation
    :param eval_env_kwargs: keyword arguments of the evaluated task if they differ (the zoo's ``--eval-env-kwargs``;
        empty: ``env_kwargs``), e.g. Maze2D trained on uniform goals and evaluated on the far goal
    :param checkpoints: models kept during training besides the final one, evenly spaced (the zoo's ``--save-freq``
        of ``steps // checkpoints`` env steps), for a later stage that chooses among them; 0: the final model only
    :param conf_dir: the folder of ``hyperparams/`` that holds ``conf_file`` for this stage, ending with ``/`` (e.g.
        ``image/``, the pixel recipe), in place of the budget's ``conf_dir`` and the challenge's recipe; None: those
    :param eval_freq: env steps between two evaluations; 0: the budget's ``n_evals`` per stage
    :param eval_episodes: episodes per evaluation; 0: the budget's ``eval_episodes``
    :param checkpoint_freq: env steps between two resumable checkpoints (the zoo's ``--checkpoint-freq``: model,
        optimizers, replay buffer); a stage stopped with one in its folder continues from it at the next run (the
        zoo's ``--resume``) instead of starting over; 0: none
    """

    name: str
    algo: str
    env_id: str
    conf_file: str
    params: Params | None = None
    needs: tuple[str, ...] = ()
    method: str | None = None
    save_replay_buffer: bool = False
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    eval_env_kwargs: dict[str, Any] = field(default_factory=dict)
    checkpoints: int = 0
    conf_dir: str | None = None
    eval_freq: int = 0
    eval_episodes: int = 0
    checkpoint_freq: int = 0

    def __post_init__(self) -> None:
        for name in ("checkpoints", "eval_freq", "eval_episodes", "checkpoint_freq"):
            check_number(f"{self.name}: {name}", getattr(self, name), minimum=0, integer=True)
        if self.conf_dir is not None and not self.conf_dir.endswith("/"):
            raise ValueError(f"{self.name}: conf_dir is a folder of hyperparams/ ending with '/', got {self.conf_dir!r}.")

    def output(self, stage_dir: Path) -> Path:
        """The trained model's zip."""
        run_dir = zoo_run_dir(stage_dir, self.algo, self.env_id)
        return run_dir / f"{self.env_id.replace('/', '-')}.zip"

    def conf_file_at(self, ctx: StageContext) -> str:
        """
        The YAML the stage reads, relative to ``hyperparams/``: the stage's own ``<conf_dir><conf_file>`` where it names
        a folder; else ``<conf_dir><recipe>/<conf_file>`` (the budget's ``conf_dir``) where the challenge's recipe (read
        at this budget) has that file, else ``<conf_dir><conf_file>``.
        """
        if self.conf_dir is not None:
            return self.conf_dir + self.conf_file
        if ctx.recipe is not None and (hyperparams_dir() / ctx.budget.conf_dir / ctx.recipe / self.conf_file).is_file():
            return f"{ctx.budget.conf_dir}{ctx.recipe}/{self.conf_file}"
        return ctx.budget.conf_dir + self.conf_file

    def preset(self, ctx: StageContext) -> dict[str, Any]:
        """
        The stage's YAML entry (:meth:`conf_file_at`, its task's entry): the hyperparameters that the budget's and the
        stage's ``-params`` override.

        :raise ValueError: when the file is missing (e.g. a recipe written for the cpu budget only, at ``paper``) or has
            no entry for the stage's task (naming the entries it has)
        """
        conf_file = self.conf_file_at(ctx)
        path = hyperparams_dir() / conf_file
        if not path.is_file():
            found = sorted(str(other.relative_to(hyperparams_dir())) for other in hyperparams_dir().rglob(self.conf_file))
            raise ValueError(
                f"Stage {self.name!r} reads hyperparams/{conf_file} at the {ctx.budget.name} budget: no such file "
                f"(hyperparams/ has {', '.join(found) or 'none of that name'}: a budget that reads its folder runs it)."
            )
        entries = _yaml_entries(path, path.stat().st_mtime_ns)
        if self.env_id not in entries:
            raise ValueError(
                f"Stage {self.name!r}: hyperparams/{conf_file} has no entry {self.env_id!r} (its entries: "
                f"{', '.join(entries)})."
            )
        return copy.deepcopy(entries[self.env_id])

    def env_steps(self, ctx: StageContext) -> int:
        """The env steps it trains for: the budget's for this stage, else the conf file's ``n_timesteps``."""
        return ctx.steps.get(self.name) or int(self.preset(ctx)["n_timesteps"])

    def zoo_args(self, ctx: StageContext, stage_dir: Path) -> list[str]:
        """
        Arguments of ``python -m sb3_pilot.experiments.zoo`` for this stage (but verbosity). The merge rule: the YAML
        entry (:meth:`preset`), then the budget's ``hyperparams``, then the stage's ``params``, each key replacing the
        one before, but ``policy_kwargs``, merged key by key (the entry's ``net_arch``, a budget's ``net_arch`` and a
        stage's ``freeze_state_planner`` all hold); ``-params`` holds what the budget and the stage set.
        """
        conf_file = self.conf_file_at(ctx)
        entry = self.preset(ctx)
        steps = self.env_steps(ctx)
        layers = [
            # a buffer larger than the run is never filled: allocate (and save) only what is used
            {"buffer_size": min(int(entry["buffer_size"]), max(steps, 1000))},
            ctx.budget.hyperparams,
            self.params(ctx.outputs) if self.params else {},
        ]
        hyperparams: dict[str, Any] = {key: value for layer in layers for key, value in layer.items()}
        if "policy_kwargs" in hyperparams:  # the zoo would replace the entry's: merged here, key by key
            layers.insert(0, {"policy_kwargs": zoo_value(entry.get("policy_kwargs", {}))})
            hyperparams["policy_kwargs"] = {
                key: value for layer in layers for key, value in layer.get("policy_kwargs", {}).items()
            }
        # HER cannot sample before an episode has ended: SB3's default (100) is too early with 4 x 500-step envs
        env_kwargs = self.env_kwargs or entry.get("env_kwargs", {})  # the zoo's --env-kwargs replace the YAML's
        if self.env_id not in gym.registry:
            register()  # gymnasium-robotics' own IDs, which the zoo entry registers
        episode_steps = env_kwargs.get("max_episode_steps") or gym.spec(self.env_id).max_episode_steps or 1
        first_episodes = hyperparams.get("n_envs", entry.get("n_envs", 1)) * episode_steps
        if first_episodes > hyperparams.get("learning_starts", entry.get("learning_starts", 100)):
            hyperparams["learning_starts"] = first_episodes
        # -params callback replaces the YAML's, as in the zoo: so the YAML's (MEGA's, sac_mega.yml) is kept unless the
        # stage computes its own (a transfer callback with the source's path), beside the CSV logger
        callbacks = hyperparams.pop("callback", None)
        if callbacks is None:
            callbacks = entry.get("callback", [])
            callbacks = callbacks if isinstance(callbacks, list) else [callbacks]
        hyperparams["callback"] = [{f"{__name__}.CSVLogger": {"folder": str(stage_dir)}}, *callbacks]
        args = ["train", "--algo", self.algo, "--env", self.env_id, "--conf-file", conf_file, "-f", str(stage_dir)]
        args += ["--seed", str(ctx.seed), "-n", str(steps), "--num-threads", str(ctx.threads)]
        eval_freq = self.eval_freq or max(steps // ctx.budget.n_evals, 1)
        args += ["--eval-freq", str(eval_freq), "--eval-episodes", str(self.eval_episodes or ctx.budget.eval_episodes)]
        if self.checkpoints:  # only then in the command: the other stages' hashes stay
            args += ["--save-freq", str(max(steps // self.checkpoints, 1))]
        if self.checkpoint_freq:  # the same
            args += ["--checkpoint-freq", str(self.checkpoint_freq)]
        args += ["-params", *(f"{key}:{zoo_text(value)}" for key, value in hyperparams.items())]
        if self.env_kwargs:
            args += ["--env-kwargs", *(f"{key}:{value!r}" for key, value in self.env_kwargs.items())]
        if self.eval_env_kwargs:
            args += ["--eval-env-kwargs", *(f"{key}:{value!r}" for key, value in self.eval_env_kwargs.items())]
        return [*args, "--save-replay-buffer"] if self.save_replay_buffer else args

    def config(self, ctx: StageContext, stage_dir: Path) -> dict[str, Any]:
        """
        What decides the stage's result (hashed for resuming): its zoo command line and the conf file's entry under it
        (a changed preset makes a stage trained under the old one stale).
        """
        return {"zoo": self.zoo_args(ctx, stage_dir), "preset": self.preset(ctx)}

    def describe(self, ctx: StageContext, stage_dir: Path) -> str:
        """A short line for the progress display (the whole command: :meth:`command`)."""
        return f"{self.algo} on {self.env_id}, {self.env_steps(ctx)} env steps"

    def command(self, ctx: StageContext, stage_dir: Path, resume: bool = False) -> str:
        """
        The command line that runs the stage, as a shell would read it.

        :param resume: continue from the checkpoint in ``stage_dir`` (the zoo's ``--resume``)
        """
        return f"python -m sb3_pilot.experiments.zoo {shlex.join(self._argv(ctx, stage_dir, resume))}"

    def _argv(self, ctx: StageContext, stage_dir: Path, resume: bool = False) -> list[str]:
        return [*self.zoo_args(ctx, stage_dir), "--verbose", str(ctx.verbose), *(["--resume"] if resume else [])]

    def run(self, ctx: StageContext, stage_dir: Path, resume: bool = False) -> None:
        """
        Train through the zoo (in this process).

        :param resume: continue from the checkpoint in ``stage_dir`` (:meth:`checkpoint`)
        """
        from sb3_pilot.experiments import zoo

        zoo.main(self._argv(ctx, stage_dir, resume))

    def checkpoint(self, stage_dir: Path) -> dict[str, Any] | None:
        """
        The resumable checkpoint in the stage's folder (:attr:`checkpoint_freq`): its ``checkpoint.json``
        (``num_timesteps``, its env steps; ``training_s``, the training's wall time to reach it, where recorded), None
        without one.
        """
        run_dir = zoo_run_dir(stage_dir, self.algo, self.env_id)
        path = run_dir / PilotExperimentManager.CHECKPOINT_FOLDER / CHECKPOINT_FILE
        return json.loads(path.read_text()) if path.is_file() else None

    def curve(self, stage_dir: Path) -> tuple[list[int], list[float]]:
        """Success rate of the zoo's evaluations (``evaluations.npz``) against env steps."""
        evaluations = np.load(zoo_run_dir(stage_dir, self.algo, self.env_id) / "evaluations.npz")
        return evaluations["timesteps"].tolist(), evaluations["successes"].mean(axis=1).tolist()

    def distances(self, stage_dir: Path) -> list[float] | None:
        """
        Mean final distance to the goal of each evaluation (``GoalEvalCallback``'s ``final_distances``), None for a
        run that has none.
        """
        distances = load_final_distances(zoo_run_dir(stage_dir, self.algo, self.env_id) / "evaluations.npz")
        return None if distances is None else distances.tolist()


@dataclass(frozen=True)
class Distill:
    """
    Distil a teacher stage (any off-policy goal agent; a UDPO trained with ``save_replay_buffer`` for labels that read
    its buffer) into a goal planner, saved as ``planner.pt``; the held-out agreement with the teacher goes to
    ``distill.json``.

    :param name: stage name
    :param source: the teacher's :class:`ZooTrain` stage
    :param env_kwargs: options of the task the teacher's rollouts run in, over those it trained with (e.g.
        ``{"reset_target": True}``: a PointMaze goal that moves on once reached, so that the rollouts do not hover at
        their goals)
    """

    name: str
    source: str
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    method = None

    @property
    def needs(self) -> tuple[str, ...]:
        return (self.source,)

    def output(self, stage_dir: Path) -> Path:
        """The goal planner's file."""
        return stage_dir / "planner.pt"

    def config(self, ctx: StageContext, stage_dir: Path) -> dict[str, Any]:
        # the rollouts' options only where given: the other challenges' hashes stay
        rollouts = {"env_kwargs": self.env_kwargs} if self.env_kwargs else {}
        return {"source": str(ctx.outputs[self.source]), "seed": ctx.seed, **ctx.budget.distill, **rollouts}

    def describe(self, ctx: StageContext, stage_dir: Path) -> str:
        return f"distil the goal planner of {self.source}"

    def run(self, ctx: StageContext, stage_dir: Path) -> None:
        """Load the teacher (with its replay buffer, if saved), distil (its rollouts on the task options it trained with,
        ``env_kwargs`` over them), save."""
        model_path = ctx.outputs[self.source]
        env_id, env_kwargs = zoo_env_id(model_path), {**zoo_env_kwargs(model_path), **self.env_kwargs}
        register()  # the teacher's task may be gymnasium-robotics'
        teacher, _ = load_zoo_model(model_path, env=DummyVecEnv([lambda: gym.make(env_id, **env_kwargs)]))
        if (model_path.parent / "replay_buffer.pkl").is_file():  # a source trained with save_replay_buffer
            teacher.load_replay_buffer(model_path.parent / "replay_buffer.pkl")
        planner = distill_goal_planner(teacher, source_task=env_id, seed=ctx.seed, verbose=ctx.verbose, **ctx.budget.distill)
        stage_dir.mkdir(parents=True, exist_ok=True)
        planner.save(self.output(stage_dir))
        (stage_dir / "distill.json").write_text(json.dumps(planner.metadata["holdout"], indent=2))


class ShippedFileMissing(FileNotFoundError):
    """A shipped file (a trained model or planner in the repository's ``zoo_runs/``) is not there: the package was
    installed without the repository."""


def shipped_file(path: Path) -> Path:
    """
    :param path: a file that comes with the repository (under ``zoo_runs/``)
    :return: ``path``, if it is there
    :raises ShippedFileMissing: if it is not, saying where the shipped files are
    """
    if not path.is_file():
        where = path.relative_to(REPO_DIR) if path.is_relative_to(REPO_DIR) else path
        raise ShippedFileMissing(
            f"The shipped file {where} is not here: the shipped models and planners are in the repository's "
            "zoo_runs/, not in the installed package. Run from a clone of the repository (pip install -e .)."
        )
    return path


@dataclass(frozen=True)
class Shipped:
    """
    A file that comes with the repository (a trained controller, a distilled planner) standing in for the stage that
    would make it: nothing runs, and its hash is the file's content and that of the ``VecNormalize`` statistics
    :func:`load_zoo_model` reads beside a model (where there are any), so a stage reading it runs again when either
    changes.

    :param name: stage name (key of its output)
    :param path: the file
    """

    name: str
    path: Path
    method = None
    needs: tuple[str, ...] = ()

    def output(self, stage_dir: Path) -> Path:
        """The shipped file."""
        return self.path

    def config(self, ctx: StageContext, stage_dir: Path) -> dict[str, Any]:
        config = {"shipped": str(self.path), "sha256": hashlib.sha256(shipped_file(self.path).read_bytes()).hexdigest()}
        stats = vecnormalize_path(self.path)
        if stats.exists():
            config["vecnormalize_sha256"] = hashlib.sha256(stats.read_bytes()).hexdigest()
        return config

    def describe(self, ctx: StageContext, stage_dir: Path) -> str:
        return f"shipped {self.path.name}"

    def run(self, ctx: StageContext, stage_dir: Path) -> None:
        """Nothing to run: the file is there (its hash was taken when planning)."""


Stage = ZooTrain | Distill | Shipped


def config_hash(config: dict[str, Any], needs_hashes: list[str]) -> str:
    """Hash of a stage's configuration and of the hashes of the stages it reads from."""
    text = json.dumps({"config": config, "needs": needs_hashes}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


#: Stands for the challenge's output folder in stored configurations, so that a moved or copied folder still resumes.
RUN_DIR = "<run>"
#: The repository's folder (its shipped files, :class:`Shipped`), and what stands for it in stored configurations.
#: Installed from a wheel it is the folder holding the package, with no ``zoo_runs/``: :func:`shipped_file` says so.
REPO_DIR, REPO = Path(__file__).resolve().parents[3], "<repo>"


def portable(config: dict[str, Any], run_dir: Path) -> dict[str, Any]:
    """
    A stage configuration with the challenge's folder written :data:`RUN_DIR` and then the repository's (shipped
    files) :data:`REPO`: what is hashed and stored.

    :param config: the configuration (JSON-serialisable but for paths)
    :param run_dir: ``<root>/<challenge>``
    """
    return json.loads(json.dumps(config, default=str).replace(str(run_dir), RUN_DIR).replace(str(REPO_DIR), REPO))
