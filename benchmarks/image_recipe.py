"""
The pixel recipe's measurements and the image budget's sizing (issue 41): SAC + HER on an image task with the preset
``hyperparams/image/sac.yml`` and its variants, each (variant, seed) one RL-Zoo run, resumable, then a table per variant.

Variants (``+`` combines them, e.g. ``hidden+stack3``):

- ``drawn``: the preset itself (the target drawn in the frame, DrQ's ``random_shift=4``);
- ``hidden``: the target hidden from the frame (``--env-kwargs show_target:False``);
- ``noshift``: no random shift (the preset's ``policy_kwargs`` with ``random_shift=0``);
- ``goalnorm``: the goal entries standardised by the zoo's ``VecNormalize`` (``-params normalize:...``, the frames
  untouched), as the vector agents' entries are;
- ``stack3``: the last 3 frames of the image entry stacked (``sb3_pilot.common.wrappers.ImageFrameStack``,
  ``n_frames=3``, after the preset's own ``env_wrapper``);
- ``zoorl``: the RL settings under which the vector sources learn (RL-Zoo's FetchReach ones, as the challenges'
  ``hyperparams/cpu/fetch/``): gamma 0.95, learning rate 1e-3, 1000 warm-up steps, one env with a gradient step per env step
  (the preset: gamma 0.99, 3e-4, 4 envs and a gradient step per 2 env steps); minibatches and networks unchanged;
- ``goalpred``: the encoder also trained to predict the achieved goal (``PixelGoalSACPolicy``'s
  ``goal_prediction=1.0``), which needs the package's SAC: ``--algo lean_sac`` (SB3's SAC's numbers otherwise);
- ``cheap``: the Fetch frames drawn without multisampling (``--env-kwargs antialias:False``, about 3x cheaper to
  render on CPU; Fetch tasks only);
- ``pilot``: HER + PILoT instead of SAC + HER: ``hyperparams/image/sac_pilot.yml`` (the same entry with the bonus
  wrapper, ``displacement_cosine``, ``beta = 1``, and ``PilotHerReplayBuffer``) on the goal planner of ``--planner``
  (a path with ``{seed}``: a planner per seed, e.g. distilled by ``challenges vec-to-image --stages distill``);
- ``fast``: the GPU fast path, under the package's SAC: its gradient step captured as CUDA graphs
  (``cuda_graphs=True``) and the HER buffer's frames, relabelling and rewards on the model's device (the preset's
  ``replay_buffer_kwargs`` with ``storage="device"``). It changes how fast a run goes, not what it learns, but for
  the random streams; off CUDA the step stays eager (with a warning) and the buffer's tensors stay on the CPU.

Each run is ``python -m sb3_pilot.experiments.zoo train --algo sac --env TASK --conf-file image/sac.yml --seed S
-n STEPS --eval-freq F --eval-episodes E --num-threads 1 -f . [--device D] [the variant's --env-kwargs / -params]``,
run with ``OMP_NUM_THREADS=1`` in its own folder ``ROOT/<variant>/seed_<S>/``, beside ``command.txt`` (that command),
``train.log`` (its output) and ``status.json`` (wall seconds, exit status, whether the time limit stopped it); the
zoo writes ``sac/<env name>_1/evaluations.npz`` there (``successes``, ``final_distances``). A run whose evaluations
reach ``--steps`` is finished and skipped; any other is cleared and started again from scratch, unless it resumes:
with ``--checkpoint-freq N`` each run keeps a checkpoint (the zoo's ``--checkpoint-freq N``: model, optimizers,
replay buffer with its frames compressed; every ``N`` env steps and when it stops), and ``--resume`` continues each
unfinished run from its checkpoint (the zoo's ``--resume``) instead of starting it again; a run started without one
is refused before anything runs (without ``--resume``, it starts again). A folder run with
another command (other steps, evaluations or variant; ``--device`` aside) is refused before anything runs: use
another ``--root``. Up to ``--jobs`` runs go side by side; ``--time-limit S`` stops (SIGINT: the zoo saves its model
and exits; killed after :data:`GRACE_S` seconds) the runs still going S seconds after the start, keeping their
evaluations so far, and starts no new one; such runs are unfinished and start again at the next call.

At the end, ``ROOT/summary.md`` and ``ROOT/summary.json`` (also printed), with the command that made them: per variant,
the success (IQM and mean over seeds) and the final distance to the goal at each evaluated step, each seed's steps to
0.5 success (its first evaluation at or above it) and their IQM (a seed that never reached it counts at ``--steps``
plus one evaluation interval), and the wall-clock env steps per second (evaluations included). The IQM is rliable's
(``scipy.stats.trim_mean`` cutting 25% at each end; the plain mean under 4 seeds), computed without rliable, which the
GPU machine lacks.

On CPU (about 30 env steps/s per run and core; a session's processes die with it, so call it again in the next one;
finished runs are kept)::

    OMP_NUM_THREADS=1 MUJOCO_GL=osmesa nohup python -m benchmarks.image_recipe --task Pilot/ReacherImage-v0 \\
        --variants drawn hidden noshift stack3 --seeds 0 1 --steps 50000 --root runs/image-recipe --jobs 1 &

On a lent 16-core GPU machine (no package registry, 10 minutes a call): ``benchmarks/gpu_image_recipe.sh``, which
installs the carried wheels (``benchmarks/gpu_wheels.sh``), renders with EGL, runs 2 variants x 2 seeds side by side
(the sources' RL settings and a 3-frame stack, with and without the goal prediction; on the fast path where a short
run of it finishes there) with ``--device cuda --time-limit``, and returns the table and the runs' evaluations in
``$OUT``::

    run(command="bash benchmarks/gpu_image_recipe.sh", carry=[".gpu_wheels"], timeout_s=600)

``--report`` writes the table of what ``--root`` holds, starting nothing (e.g. of the GPU runs, unpacked).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy.stats import trim_mean

from sb3_pilot.experiments.zoo import hyperparams_dir

#: The preset every run reads (``--conf-file``, in the package's ``hyperparams/``).
CONF_FILE = "image/sac.yml"
#: The same recipe with the PILoT bonus (the ``pilot`` variant).
PILOT_CONF_FILE = "image/sac_pilot.yml"
#: How a run's command calls the zoo entry, after ``python``.
ZOO = ("-m", "sb3_pilot.experiments.zoo")
#: The frame stack of the ``stack3`` variant.
FRAME_STACK = "sb3_pilot.common.wrappers.ImageFrameStack"
#: The ``goalnorm`` variant's ``normalize``: the goal entries only (the vector sources' agents see every entry
#: standardised; a pixel agent's raw goals are about 5 times smaller than its image features, 2 inputs of 258).
GOAL_NORMALIZE = "dict(norm_obs_keys=['achieved_goal', 'desired_goal'], norm_reward=False)"
#: The ``goalpred`` variant's weight of the goal-prediction loss.
GOAL_PREDICTION = 1.0
#: Seconds a run stopped by the time limit has to save and exit before it is killed.
GRACE_S = 30.0
#: The bonus wrapper's name in :data:`PILOT_CONF_FILE`'s ``env_wrapper``.
BONUS_WRAPPER = "sb3_pilot.PilotBonusWrapper"
#: Success rate whose first step is reported.
THRESHOLD = 0.5
#: Fraction of the seeds the IQM cuts at each end (rliable's ``aggregate_iqm``, ``sb3_pilot.experiments.statistics``).
IQM_CUT = 0.25


@dataclass
class Changes:
    """
    What a variant changes in the preset: the zoo algorithm, the task's kwargs, the policy's, the extractor's and the
    replay buffer's kwargs, wrappers added after the preset's and other hyperparameters (set as they are).
    """

    algo: str = "sac"
    conf_file: str = CONF_FILE
    bonus: bool = False
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    policy_kwargs: dict[str, Any] = field(default_factory=dict)
    extractor_kwargs: dict[str, Any] = field(default_factory=dict)
    wrappers: list[dict[str, Any]] = field(default_factory=list)
    replay_buffer_kwargs: dict[str, Any] = field(default_factory=dict)
    hyperparams: dict[str, Any] = field(default_factory=dict)


def _hidden(changes: Changes) -> None:
    changes.env_kwargs["show_target"] = False


def _noshift(changes: Changes) -> None:
    changes.extractor_kwargs["random_shift"] = 0


def _stack3(changes: Changes) -> None:
    changes.wrappers.append({FRAME_STACK: {"n_frames": 3}})


def _goalnorm(changes: Changes) -> None:
    # the zoo's VecNormalize on the goal entries only (the frames stay uint8); a string, which the zoo evaluates.
    # The frames transposed below it: the zoo would put its VecTransposeImage above the VecNormalize, whose original
    # (untransposed) observations SB3's off-policy algorithms store (rl-baselines3-zoo issue 312)
    changes.hyperparams["normalize"] = GOAL_NORMALIZE
    changes.hyperparams["vec_env_wrapper"] = "stable_baselines3.common.vec_env.VecTransposeImage"


def _zoorl(changes: Changes) -> None:
    settings = yaml.safe_load((hyperparams_dir() / "cpu" / "fetch" / "sac.yml").read_text())["Pilot/FetchReach-v0"]
    changes.hyperparams.update(gamma=settings["gamma"], learning_rate=settings["learning_rate"])
    changes.hyperparams.update(learning_starts=settings["learning_starts"], n_envs=1, train_freq=1, gradient_steps=1)


def _goalpred(changes: Changes) -> None:
    # the auxiliary loss is added by the package's SAC (LeanSAC: SB3's SAC's numbers otherwise)
    changes.algo = "lean_sac"
    changes.policy_kwargs["goal_prediction"] = GOAL_PREDICTION


def _cheap(changes: Changes) -> None:
    changes.env_kwargs["antialias"] = False


def _pilot(changes: Changes) -> None:
    # the bonus wrapper of PILOT_CONF_FILE's entry, on the seed's planner (plan_runs)
    changes.conf_file = PILOT_CONF_FILE
    changes.bonus = True


def _fast(changes: Changes) -> None:
    # LeanSAC's fast path: CUDA graphs and the device-resident HER buffer (eager, on CPU tensors, off CUDA)
    changes.algo = "lean_sac"
    changes.hyperparams["cuda_graphs"] = True
    changes.replay_buffer_kwargs["storage"] = "device"


#: The variants, each with what it changes in the preset and its description.
VARIANTS: dict[str, tuple[Callable[[Changes], None], str]] = {
    "drawn": (lambda changes: None, "the preset: target drawn, random_shift=4"),
    "hidden": (_hidden, "target hidden from the frame (show_target=False)"),
    "noshift": (_noshift, "no random shift (random_shift=0)"),
    "stack3": (_stack3, "3 frames of the image entry stacked (ImageFrameStack)"),
    "goalnorm": (_goalnorm, "the goal entries standardised by the zoo's VecNormalize (frames untouched)"),
    "zoorl": (
        _zoorl,
        "the vector sources' RL settings: gamma 0.95, lr 1e-3, 1000 warm-up steps, 1 env, a gradient step per env step",
    ),
    "goalpred": (_goalpred, f"the encoder also predicts the achieved goal (goal_prediction={GOAL_PREDICTION}, lean_sac)"),
    "cheap": (_cheap, "Fetch frames without multisampling (antialias=False)"),
    "pilot": (_pilot, f"HER + PILoT: hyperparams/{PILOT_CONF_FILE}'s bonus (displacement_cosine) on --planner's planner"),
    "fast": (_fast, "the GPU fast path: CUDA graphs and the HER buffer on the device (lean_sac)"),
}


def parse_variant(name: str) -> Changes:
    """
    :param name: a variant of :data:`VARIANTS`, or several joined by ``+``
    :return: its changes to the preset
    :raises ValueError: naming an unknown or repeated part
    """
    parts = name.split("+")
    unknown = [part for part in parts if part not in VARIANTS]
    if unknown:
        raise ValueError(f"Unknown variant part(s) {unknown} in {name!r}; the variants: {', '.join(VARIANTS)} (join with +).")
    if len(set(parts)) != len(parts) or ("drawn" in parts and len(parts) > 1):
        raise ValueError(f"Variant {name!r} repeats a part or combines 'drawn' (the preset itself) with others.")
    changes = Changes()
    for part in parts:
        VARIANTS[part][0](changes)
    return changes


def describe(name: str) -> str:
    """The variant's description (its parts', joined)."""
    return "; ".join(VARIANTS[part][1] for part in name.split("+"))


def preset_entry(task: str, conf_file: str = CONF_FILE) -> dict[str, Any]:
    """
    :param task: a Gymnasium ID
    :param conf_file: the preset's file under ``hyperparams/``
    :return: the task's entry in ``conf_file``
    :raises ValueError: if the file has none (the task has no image preset), naming the tasks it has
    """
    entries = yaml.safe_load((hyperparams_dir() / conf_file).read_text())
    if task not in entries:
        raise ValueError(
            f"--task {task} has no entry in hyperparams/{conf_file} (no image preset); its tasks: {', '.join(entries)}."
        )
    return entries[task]


def literal(value: Any) -> str:
    """A Python literal of ``value`` (dicts, lists, tuples of strings and numbers) with double-quoted strings, which the
    zoo's ``-params`` evaluates and which ``command.txt`` shows without shell escapes."""
    if isinstance(value, dict):
        return "{" + ", ".join(f"{literal(key)}: {literal(item)}" for key, item in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        items = ", ".join(literal(item) for item in value) + ("," if isinstance(value, tuple) and len(value) == 1 else "")
        return f"[{items}]" if isinstance(value, list) else f"({items})"
    return json.dumps(value) if isinstance(value, str) else repr(value)


def entry_kwargs(entry: dict[str, Any], key: str) -> dict[str, Any]:
    """A preset entry's kwargs (``policy_kwargs``, ``replay_buffer_kwargs``) as the zoo reads them: a string evaluated."""
    value = entry.get(key, {})
    return dict(eval(value) if isinstance(value, str) else value)


def variant_args(entry: dict[str, Any], changes: Changes, planner: str | None = None) -> list[str]:
    """
    :param entry: the preset's entry
    :param changes: a variant's
    :param planner: the goal planner of the bonus wrapper (``pilot``; its entry's wrapper has another path)
    :return: the zoo arguments (``--env-kwargs``, ``-params``) that make ``entry`` the variant of ``changes``
    """
    args: list[str] = []
    if changes.env_kwargs:
        args += ["--env-kwargs", *(f"{key}:{literal(value)}" for key, value in changes.env_kwargs.items())]
    params = []
    if changes.extractor_kwargs or changes.policy_kwargs:
        policy_kwargs = entry_kwargs(entry, "policy_kwargs")
        policy_kwargs.update(changes.policy_kwargs)
        if changes.extractor_kwargs:
            extractor_kwargs = {**policy_kwargs.get("features_extractor_kwargs", {}), **changes.extractor_kwargs}
            policy_kwargs["features_extractor_kwargs"] = extractor_kwargs
        params.append(f"policy_kwargs:{literal(policy_kwargs)}")
    if changes.replay_buffer_kwargs:
        buffer_kwargs = {**entry_kwargs(entry, "replay_buffer_kwargs"), **changes.replay_buffer_kwargs}
        params.append(f"replay_buffer_kwargs:{literal(buffer_kwargs)}")
    if changes.wrappers or planner is not None:
        wrappers = entry.get("env_wrapper") or []
        wrappers = [wrappers] if isinstance(wrappers, (str, dict)) else list(wrappers)
        if planner is not None:
            wrappers = [
                {name: {**kwargs, "planner": planner} for name, kwargs in wrapper.items()}
                if isinstance(wrapper, dict) and BONUS_WRAPPER in wrapper
                else wrapper
                for wrapper in wrappers
            ]
        params.append(f"env_wrapper:{literal(wrappers + changes.wrappers)}")
    params += [f"{key}:{literal(value)}" for key, value in changes.hyperparams.items()]
    return [*args, "-params", *params] if params else args


@dataclass
class Run:
    """One (variant, seed) run: its folder and its zoo arguments (the device apart)."""

    variant: str
    seed: int
    folder: Path
    args: list[str]

    def command(self, device: str | None) -> list[str]:
        """The run's command, as written in ``command.txt`` (``python`` being this Python)."""
        return ["python", *ZOO, *self.args, *(["--device", device] if device else [])]


def plan_runs(args: argparse.Namespace) -> list[Run]:
    """
    The runs of the command line, every input checked before any work.

    :raises ValueError: naming the bad input
    """
    entry = preset_entry(args.task)
    if args.steps < 1 or args.eval_freq < 1 or args.eval_episodes < 1:
        raise ValueError("--steps, --eval-freq and --eval-episodes must be positive.")
    # the envs of each variant (zoorl sets one), whose vector steps the zoo's evaluations count
    n_envs = math.lcm(*(int(parse_variant(name).hyperparams.get("n_envs", entry.get("n_envs", 1))) for name in args.variants))
    if args.eval_freq % n_envs or args.steps % args.eval_freq:
        raise ValueError(
            f"--eval-freq ({args.eval_freq}) must be a multiple of the variants' n_envs ({n_envs}) and --steps "
            f"({args.steps}) a multiple of --eval-freq, so that the last evaluation is at --steps."
        )
    if len(set(args.seeds)) != len(args.seeds) or min(args.seeds) < 0:
        raise ValueError(f"--seeds must be distinct non-negative integers, got {args.seeds}.")
    if len(set(args.variants)) != len(args.variants):
        raise ValueError(f"--variants repeats a variant: {args.variants}.")
    if args.jobs < 1 or (args.time_limit is not None and args.time_limit <= 0):
        raise ValueError("--jobs must be at least 1 and --time-limit positive.")
    if any(parse_variant(name).bonus for name in args.variants):
        if args.planner is None or "{seed}" not in args.planner:
            raise ValueError("The pilot variant needs --planner, a path with {seed} (a goal planner per seed).")
        missing = [args.planner.format(seed=seed) for seed in args.seeds if not Path(args.planner.format(seed=seed)).is_file()]
        if missing:
            raise ValueError(f"--planner: no planner at {', '.join(missing)}.")
    if args.checkpoint_freq < 0:
        raise ValueError(f"--checkpoint-freq must be >= 0 (0: no checkpoint), got {args.checkpoint_freq}.")
    if args.resume and not args.checkpoint_freq:
        raise ValueError("--resume continues the runs from their checkpoints: give the --checkpoint-freq they run with.")
    runs = []
    for variant in args.variants:
        changes = parse_variant(variant)
        variant_entry = preset_entry(args.task, changes.conf_file)
        base = ["train", "--algo", changes.algo, "--env", args.task, "--conf-file", changes.conf_file]
        for seed in args.seeds:
            # the runs start in their own folders: the planner's absolute path
            planner = str(Path(args.planner.format(seed=seed)).resolve()) if changes.bonus else None
            settings = ["--seed", str(seed), "-n", str(args.steps), "--eval-freq", str(args.eval_freq)]
            settings += ["--eval-episodes", str(args.eval_episodes), "--num-threads", "1", "-f", "."]
            extra = variant_args(variant_entry, changes, planner)
            settings += ["--checkpoint-freq", str(args.checkpoint_freq)] if args.checkpoint_freq else []
            runs.append(Run(variant, seed, Path(args.root, variant, f"seed_{seed}"), [*base, *settings, *extra]))
    return runs


def recorded_args(folder: Path) -> list[str] | None:
    """The zoo arguments of the command in ``folder/command.txt`` (the device apart), None without one."""
    path = folder / "command.txt"
    if not path.is_file():
        return None
    words = shlex.split(path.read_text())[1 + len(ZOO) :]
    if "--device" in words:
        index = words.index("--device")
        del words[index : index + 2]
    return words


def evaluations(folder: Path) -> dict[str, np.ndarray] | None:
    """
    A run's evaluations (``timesteps``, ``success_rate``, ``final_distance``), None before its first; an evaluation
    cut short by a stop (``final_distances`` one shorter) is left out.
    """
    paths = sorted(folder.glob("*/*_[0-9]*/evaluations.npz"), key=lambda path: int(path.parent.name.rsplit("_", 1)[1]))
    if not paths:
        return None
    try:
        with np.load(paths[-1]) as data:
            timesteps = np.asarray(data["timesteps"])
            successes = np.asarray(data["successes"], dtype=np.float64) if "successes" in data else None
            distances = np.asarray(data["final_distances"], dtype=np.float64) if "final_distances" in data else None
    except (OSError, ValueError, EOFError, KeyError) as error:  # a file cut while it was written
        print(f"warning: {paths[-1]} is unreadable ({error}); the run counts as unfinished", file=sys.stderr)
        return None
    if successes is None or len(timesteps) == 0:
        return None
    n = min(len(timesteps), len(successes), len(distances) if distances is not None else len(timesteps))
    return {
        "timesteps": timesteps[:n].astype(np.int64),
        "success_rate": successes[:n].mean(axis=1),
        "final_distance": distances[:n] if distances is not None else np.full(n, np.nan),
    }


def is_finished(folder: Path, steps: int) -> bool:
    """Whether the run in ``folder`` has its evaluation at ``steps``."""
    data = evaluations(folder)
    return data is not None and int(data["timesteps"][-1]) >= steps


def has_checkpoint(folder: Path) -> bool:
    """Whether the run in ``folder`` has a checkpoint to resume from (the zoo's ``--checkpoint-freq``)."""
    return any(folder.glob("*/*_[0-9]*/checkpoint/checkpoint.json"))


def check_resumable(runs: Sequence[Run], steps: int) -> None:
    """:raises ValueError: naming the unfinished runs that started without a checkpoint (``--resume`` cannot go on)."""
    missing = [str(run.folder) for run in runs if run.folder.exists() and not is_finished(run.folder, steps)]
    missing = [folder for folder in missing if not has_checkpoint(Path(folder))]
    if missing:
        raise ValueError(
            f"--resume: no checkpoint in {', '.join(missing)} (started without --checkpoint-freq, or stopped before its "
            "first): drop --resume to start them again, or remove those folders."
        )


def check_recorded(runs: Sequence[Run]) -> None:
    """:raises ValueError: if a run's folder holds a run of another command (naming both)."""
    for run in runs:
        recorded = recorded_args(run.folder)
        if recorded is not None and recorded != run.args:
            raise ValueError(
                f"{run.folder} holds a run of another command:\n  {shlex.join(recorded)}\nnot\n  {shlex.join(run.args)}\n"
                "(--device aside). Use another --root, or remove that folder."
            )


def _stamp() -> str:
    return time.strftime("%H:%M:%S")


def _start(run: Run, device: str | None, resume: bool = False) -> subprocess.Popen:
    """
    Clear the run's folder, write its command there and start it (its output to ``train.log``); with ``resume`` and a
    checkpoint there, continue it from that checkpoint instead (the folder kept, the output appended).
    """
    resume = resume and has_checkpoint(run.folder)
    if run.folder.exists() and not resume:
        shutil.rmtree(run.folder)
    run.folder.mkdir(parents=True, exist_ok=True)
    command = run.command(device)
    (run.folder / "command.txt").write_text(shlex.join(command) + "\n")
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONUNBUFFERED="1")
    with open(run.folder / "train.log", "ab" if resume else "wb") as log:
        return subprocess.Popen(
            [sys.executable, *command[1:], *(["--resume"] if resume else [])],
            cwd=run.folder,
            stdout=log,
            stderr=subprocess.STDOUT,
            env=env,
            start_new_session=True,
            # SIGINT as Python's default (KeyboardInterrupt: the zoo saves), even where this runner inherited it
            # ignored (started with `nohup ... &` from a script), which the child would inherit in turn
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )


def _stop(processes: dict[int, tuple[Run, subprocess.Popen, float]], stopped: set[int]) -> None:
    """SIGINT to the running ones (the zoo saves and exits), then kill those still running after :data:`GRACE_S`."""
    for index, (_, process, _) in processes.items():
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
            stopped.add(index)
    deadline = time.monotonic() + GRACE_S
    for _, process, _ in processes.values():
        try:
            process.wait(timeout=max(deadline - time.monotonic(), 0.1))
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def execute(
    runs: Sequence[Run], device: str | None, jobs: int, time_limit: float | None, steps: int, resume: bool = False
) -> None:
    """
    Run the unfinished ``runs``, ``jobs`` at a time, stopping all at ``time_limit`` seconds, those with a checkpoint
    resumed from it with ``resume`` (see the module doc).
    """
    todo = [index for index, run in enumerate(runs) if not is_finished(run.folder, steps)]
    for run in runs:
        if is_finished(run.folder, steps):
            print(f"[{_stamp()}] {run.variant} seed {run.seed}: finished, skipped")
    start = time.monotonic()
    processes: dict[int, tuple[Run, subprocess.Popen, float]] = {}
    stopped: set[int] = set()

    def record(index: int, run: Run, process: subprocess.Popen, began: float) -> None:
        seconds = time.monotonic() - began
        data = evaluations(run.folder)
        last = int(data["timesteps"][-1]) if data is not None else 0
        status = {
            "returncode": process.returncode,
            "seconds": round(seconds, 1),
            "stopped_by_time_limit": index in stopped,
            "finished": last >= steps,
            "last_step": last,
            "device": device or "auto",
        }
        (run.folder / "status.json").write_text(json.dumps(status, indent=1) + "\n")
        success = f", success {data['success_rate'][-1]:.2f}" if data is not None else ""
        state = "finished" if last >= steps else "stopped" if index in stopped else f"failed ({process.returncode})"
        print(f"[{_stamp()}] {run.variant} seed {run.seed}: {state} in {seconds:.0f} s at step {last}{success}", flush=True)

    try:
        while todo or processes:
            over = time_limit is not None and time.monotonic() - start >= time_limit
            if over and processes:
                print(f"[{_stamp()}] time limit ({time_limit:.0f} s): stopping {len(processes)} run(s)", flush=True)
                _stop(processes, stopped)
            if over:
                todo = []
            while todo and len(processes) < jobs:
                index = todo.pop(0)
                how = "resumed" if resume and has_checkpoint(runs[index].folder) else "started"
                print(f"[{_stamp()}] {runs[index].variant} seed {runs[index].seed}: {how}", flush=True)
                processes[index] = (runs[index], _start(runs[index], device, resume), time.monotonic())
            for index, (run, process, began) in list(processes.items()):
                if process.poll() is not None:
                    record(index, run, process, began)
                    del processes[index]
            time.sleep(0.5)
    except KeyboardInterrupt:
        print(f"[{_stamp()}] interrupted: stopping {len(processes)} run(s)", flush=True)
        _stop(processes, stopped)
        for index, (run, process, began) in processes.items():
            record(index, run, process, began)
        raise


def iqm(values: Sequence[float]) -> float:
    """The interquartile mean (rliable's ``aggregate_iqm``: ``trim_mean`` cutting :data:`IQM_CUT` at each end)."""
    return float(trim_mean(np.asarray(values, dtype=np.float64), IQM_CUT))


def steps_to(timesteps: np.ndarray, success_rate: np.ndarray, threshold: float = THRESHOLD) -> int | None:
    """The first evaluated step whose success rate reaches ``threshold`` (None: none did)."""
    reached = np.flatnonzero(success_rate >= threshold)
    return int(timesteps[reached[0]]) if len(reached) else None


def summarise(runs: Sequence[Run], steps: int, eval_freq: int) -> dict[str, Any]:
    """Per variant: its runs' curves, the curve over seeds at each evaluated step, steps to 0.5 and speed."""
    variants: dict[str, Any] = {}
    for run in runs:
        entry = variants.setdefault(run.variant, {"description": describe(run.variant), "runs": []})
        data = evaluations(run.folder)
        if data is None:
            continue
        status_path = run.folder / "status.json"
        status = json.loads(status_path.read_text()) if status_path.is_file() else {}
        last = int(data["timesteps"][-1])
        entry["runs"].append(
            {
                "seed": run.seed,
                "timesteps": data["timesteps"].tolist(),
                "success_rate": data["success_rate"].tolist(),
                "final_distance": data["final_distance"].tolist(),
                "finished": last >= steps,
                "steps_to_50": steps_to(data["timesteps"], data["success_rate"]),
                "seconds": status.get("seconds"),
                "steps_per_s": round(last / status["seconds"], 1) if status.get("seconds") else None,
            }
        )
    censored_at = steps + eval_freq
    for entry in variants.values():
        seeds = entry["runs"]
        by_step: dict[int, list[tuple[float, float]]] = {}
        for run in seeds:
            for step, rate, distance in zip(run["timesteps"], run["success_rate"], run["final_distance"], strict=True):
                by_step.setdefault(step, []).append((rate, distance))
        curve = []
        for step, points in sorted(by_step.items()):
            rates, distances = zip(*points, strict=True)
            curve.append(
                {
                    "step": step,
                    "seeds": len(points),
                    "success_iqm": iqm(rates),
                    "success_mean": float(np.mean(rates)),
                    "final_distance_iqm": iqm(distances),
                    "final_distance_mean": float(np.mean(distances)),
                }
            )
        entry["curve"] = curve
        if seeds:
            reached = [run["steps_to_50"] for run in seeds if run["steps_to_50"] is not None]
            entry["steps_to_50"] = {
                "iqm": iqm([censored_at if run["steps_to_50"] is None else run["steps_to_50"] for run in seeds]),
                "reached": len(reached),
                "seeds": len(seeds),
                "censored_at": censored_at,
            }
            entry["final_success_iqm"] = iqm([run["success_rate"][-1] for run in seeds])
            entry["final_distance_iqm"] = iqm([run["final_distance"][-1] for run in seeds])
            speeds = [run["steps_per_s"] for run in seeds if run["steps_per_s"]]
            entry["steps_per_s"] = float(np.mean(speeds)) if speeds else None
    return variants


def _number(value: float | None, digits: int = 2) -> str:
    return "-" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def markdown(summary: dict[str, Any]) -> str:
    """The summary as Markdown: an overview row per variant, then each variant's curve and seeds."""
    lines = [
        f"# Pixel recipe on {summary['task']}: SAC + HER, hyperparams/{CONF_FILE} and variants",
        "",
        f"Command: `{summary['command']}`",
        "",
        f"Budget {summary['steps']} env steps, evaluated every {summary['eval_freq']} steps on {summary['eval_episodes']} "
        "deterministic episodes. IQM over seeds (rliable's; the plain mean under 4 seeds). Steps to 0.5: the first "
        "evaluation at or above 0.5 success; a seed that never reached it counts at "
        f"{summary['steps'] + summary['eval_freq']}. Env steps/s: wall clock, evaluations included.",
        "",
        "| variant | seeds (finished) | last step | final success IQM | final distance IQM | steps to 0.5 IQM (reached) "
        "| env steps/s |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, entry in summary["variants"].items():
        seeds = entry["runs"]
        if not seeds:
            lines.append(f"| {name} | 0 | - | - | - | - | - |")
            continue
        finished = sum(run["finished"] for run in seeds)
        lasts = sorted({run["timesteps"][-1] for run in seeds})
        last = str(lasts[0]) if len(lasts) == 1 else f"{lasts[0]}-{lasts[-1]}"
        to_50 = entry["steps_to_50"]
        lines.append(
            f"| {name} | {len(seeds)} ({finished}) | {last} | {_number(entry['final_success_iqm'])}"
            f" | {_number(entry['final_distance_iqm'], 3)} | {_number(to_50['iqm'], 0)} ({to_50['reached']}/{to_50['seeds']})"
            f" | {_number(entry['steps_per_s'], 1)} |"
        )
    for name, entry in summary["variants"].items():
        lines += ["", f"## {name}: {entry['description']}", ""]
        if not entry["runs"]:
            lines.append("No evaluations yet.")
            continue
        lines += [
            "| step | seeds | success IQM | success mean | final distance IQM | final distance mean |",
            "|---|---|---|---|---|---|",
        ]
        lines += [
            f"| {point['step']} | {point['seeds']} | {_number(point['success_iqm'])} | {_number(point['success_mean'])} | "
            f"{_number(point['final_distance_iqm'], 3)} | {_number(point['final_distance_mean'], 3)} |"
            for point in entry["curve"]
        ]
        per_seed = ", ".join(
            f"seed {run['seed']}: "
            + (str(run["steps_to_50"]) if run["steps_to_50"] is not None else f"not by {run['timesteps'][-1]}")
            + ("" if run["finished"] else " (unfinished)")
            for run in entry["runs"]
        )
        lines += ["", f"Steps to 0.5: {per_seed}."]
    return "\n".join(lines) + "\n"


def report(runs: Sequence[Run], args: argparse.Namespace, command: str) -> dict[str, Any]:
    """Write ``ROOT/summary.json`` and ``ROOT/summary.md``, print the latter, and return the summary."""
    summary = {
        "command": command,
        "task": args.task,
        "conf_file": CONF_FILE,
        "steps": args.steps,
        "eval_freq": args.eval_freq,
        "eval_episodes": args.eval_episodes,
        "variants": summarise(runs, args.steps, args.eval_freq),
    }
    root = Path(args.root)
    root.mkdir(parents=True, exist_ok=True)
    (root / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    text = markdown(summary)
    (root / "summary.md").write_text(text)
    print(text)
    return summary


def parser() -> argparse.ArgumentParser:
    result = argparse.ArgumentParser(
        prog="python -m benchmarks.image_recipe",
        description="SAC + HER on an image task with the pixel preset and its variants, resumable, then a table per variant.",
    )
    result.add_argument("--task", default="Pilot/ReacherImage-v0", help=f"a task with an entry in hyperparams/{CONF_FILE}")
    result.add_argument("--variants", nargs="+", default=["drawn", "hidden", "noshift", "stack3"], help=", ".join(VARIANTS))
    result.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    result.add_argument("--steps", type=int, default=50_000, help="env steps of each run (its last evaluation)")
    result.add_argument("--eval-freq", type=int, default=2_500, help="env steps between evaluations")
    result.add_argument("--eval-episodes", type=int, default=20)
    result.add_argument("--root", default="runs/image-recipe", help="the runs' folder")
    result.add_argument("--device", default=None, help="the zoo's --device of each run (default: the zoo's, auto)")
    result.add_argument("--jobs", type=int, default=1, help="runs side by side")
    result.add_argument("--time-limit", type=float, default=None, help="seconds after which the runs are stopped")
    result.add_argument("--planner", default=None, help="the pilot variant's goal planner per seed: a path with {seed}")
    result.add_argument(
        "--checkpoint-freq", type=int, default=0, help="env steps between two checkpoints of each run (0: none)"
    )
    result.add_argument("--resume", action="store_true", help="continue the unfinished runs from their checkpoints")
    result.add_argument("--report", action="store_true", help="only write the table of what --root holds")
    return result


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser().parse_args(argv)
    try:
        runs = plan_runs(args)
        check_recorded(runs)
        if args.resume and not args.report:
            check_resumable(runs, args.steps)
        if args.device is not None and args.device.startswith("cuda") and not args.report:
            import torch

            if not torch.cuda.is_available():
                raise ValueError(f"--device {args.device}: torch sees no CUDA device here.")
    except ValueError as error:
        raise SystemExit(f"image_recipe: {error}") from error
    if not args.report:
        execute(runs, args.device, args.jobs, args.time_limit, args.steps, args.resume)
    return report(runs, args, shlex.join(["python", "-m", "benchmarks.image_recipe", *argv]))


if __name__ == "__main__":
    main()
