"""
The GPU fast path (``LeanSAC`` or ``UDPO`` with ``cuda_graphs=True`` and ``replay_buffer_kwargs=dict(storage="device")``)
against the eager algorithms, in one run on one machine: training env steps/s (after warm-up and capture) of

- the state tasks of ``benchmarks.udpo_vs_sac`` (FetchReach-v4 with 64x64 heads, AntLocomotion with 256x256 ones, their
  settings there but a 1e5 buffer and fewer warm-up steps): ``LeanSAC`` and ``UDPO`` eager and fast, SB3's ``SAC``;
- the pixel stage (``PixelGoalSACPolicy`` + HER future x4, one env, one gradient step per env step) on
  ``Pilot/ReacherImage-v0`` and ``Pilot/FetchReachImage-v0``: NatureCNN with 64x64 heads at batch 64, and (Reacher)
  the paper's encoder with 256x256 heads at batch 256, ``LeanSAC`` eager and fast;
- ``--procs`` processes of the fast ReacherImage stage side by side (their steps/s summed);
- where a pixel step's time goes (``--split``): env step with its frame, acting, storing, sampling, the gradient
  step, eager and fast, each timed with the device synchronised.

Each case trains ``--warmup`` steps after its learning starts (the capture happens there), then ``--steps`` timed ones.
Results: one JSON line per case on stdout and in ``<out>/gpu_speed.jsonl``, a table in ``<out>/gpu_speed.md``, with the
machine, torch's version and the command. Cases left when ``--budget-s`` seconds have passed are skipped (listed).

Usage::

    MUJOCO_GL=egl python -m benchmarks.gpu_speed --device cuda --out $OUT
    MUJOCO_GL=osmesa python -m benchmarks.gpu_speed --device cpu --steps 200 --procs 0   # the CPU path, briefly
"""

import argparse
import copy
import json
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch as th
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

from benchmarks.udpo_vs_sac import TASKS
from sb3_pilot import UDPO
from sb3_pilot.common import PixelGoalSACPolicy
from sb3_pilot.envs import register_envs
from sb3_pilot.sac import LeanSAC

register_envs()
HER = dict(replay_buffer_class=HerReplayBuffer, replay_buffer_kwargs=dict(goal_selection_strategy="future", n_sampled_goal=4))
PIXEL = dict(buffer_size=20_000, gamma=0.95, learning_rate=1e-3, learning_starts=200, **HER)
#: the order of the measurements (by name prefix): the goals first, the state task's before the processes side by side
PRIORITY = (
    "reacher-image/",
    "ant-locomotion/",
    "side_by_side",
    "reacher-image-paper256/",
    "split:",
    "fetch-reach-image/",
    "fetch-reach/",
    "",
)
#: algorithm variants: (class, cuda_graphs + device-resident buffer), in the order measured (the goals' first)
VARIANTS: dict[str, tuple[type[BaseAlgorithm], bool]] = {
    "lean_sac": (LeanSAC, False),
    "lean_sac_fast": (LeanSAC, True),
    "udpo": (UDPO, False),
    "udpo_fast": (UDPO, True),
    "sac": (SAC, False),
}


@dataclass(frozen=True)
class Case:
    """
    One measurement: an env, an algorithm variant and its settings.

    :param name: the case's name (``task/variant``)
    :param env_id: registered env ID
    :param variant: key of ``VARIANTS``
    :param n_envs: envs stepped per vec step
    :param normalize: wrap in VecNormalize
    :param policy: the policy (name or class)
    :param kwargs: the algorithm's settings
    """

    name: str
    env_id: str
    variant: str
    n_envs: int = 1
    normalize: bool = False
    policy: Any = "MultiInputPolicy"
    kwargs: dict[str, Any] = field(default_factory=dict)


def pixel_case(task: str, env_id: str, variant: str, encoder: str = "nature") -> Case:
    paper = encoder == "paper"
    policy_kwargs = dict(net_arch=[256, 256] if paper else [64, 64], features_extractor_kwargs=dict(encoder=encoder))
    kwargs = dict(PIXEL, batch_size=256 if paper else 64, policy_kwargs=policy_kwargs)
    return Case(f"{task}{'-paper256' if paper else ''}/{variant}", env_id, variant, policy=PixelGoalSACPolicy, kwargs=kwargs)


def all_cases() -> list[Case]:
    cases = []
    for task, pixel_env in (("reacher-image", "Pilot/ReacherImage-v0"), ("fetch-reach-image", "Pilot/FetchReachImage-v0")):
        cases += [pixel_case(task, pixel_env, variant) for variant in ("lean_sac", "lean_sac_fast")]
    for variant in ("lean_sac", "lean_sac_fast"):
        cases.append(pixel_case("reacher-image", "Pilot/ReacherImage-v0", variant, encoder="paper"))
    for task_name, task in TASKS.items():
        kwargs = dict(task.kwargs, buffer_size=100_000, learning_starts=300)
        for variant in VARIANTS:
            variant_kwargs = dict(kwargs, **task.udpo_kwargs) if VARIANTS[variant][0] is UDPO else kwargs
            name = f"{task_name}/{variant}"
            cases.append(Case(name, task.env_id, variant, task.n_envs, task.normalize, kwargs=variant_kwargs))
    return cases


def make_model(case: Case, device: str, seed: int = 0) -> BaseAlgorithm:
    env = make_vec_env(case.env_id, n_envs=case.n_envs, seed=seed)
    if case.normalize:
        env = VecNormalize(env, gamma=case.kwargs["gamma"])
    algo, fast = VARIANTS[case.variant]
    kwargs = copy.deepcopy(case.kwargs)  # SB3 writes into policy_kwargs
    if fast:
        kwargs["cuda_graphs"] = True
        kwargs["replay_buffer_kwargs"] = dict(kwargs["replay_buffer_kwargs"], storage="device")
    return algo(case.policy, env, seed=seed, device=device, **kwargs)


def synchronize(device: str) -> None:
    if device.startswith("cuda"):
        th.cuda.synchronize()


def measure(case: Case, device: str, warmup: int, steps: int) -> dict[str, Any]:
    """Training env steps/s of a case, after its learning starts and ``warmup`` more steps."""
    start = time.perf_counter()
    model = make_model(case, device)
    model.learn(case.kwargs["learning_starts"] + warmup)
    synchronize(device)
    timed = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    synchronize(device)
    seconds = time.perf_counter() - timed
    update = getattr(model, "_cuda_graph_update", None)
    buffer = model.replay_buffer
    return dict(
        case=case.name,
        steps_per_s=round(steps / seconds, 1),
        timed_steps=steps,
        captured=bool(update is not None and update._graph is not None),
        draw_in_graph=bool(update is not None and update._key is not None and update._key[0] == "draw"),
        device_storage=getattr(buffer, "storage", "host") == "device",
        reward_on_device=getattr(buffer, "_device_reward", None) is not None,
        case_seconds=round(time.perf_counter() - start, 1),
    )


def ms_per_call(function: Callable[[], object], device: str, repeats: int) -> float:
    """Median over 3 rounds of ``repeats`` calls, in milliseconds per call, the device synchronised."""
    rounds = []
    for _ in range(3):
        synchronize(device)
        start = time.perf_counter()
        for _ in range(repeats):
            function()
        synchronize(device)
        rounds.append((time.perf_counter() - start) / repeats * 1e3)
    return round(float(np.median(rounds)), 3)


def split(case: Case, device: str, warmup: int, repeats: int = 30) -> dict[str, Any]:
    """Where a pixel env step's time goes: ms per env step (with its frame), acting, storing, sampling, gradient step."""
    model = make_model(case, device)
    model.learn(case.kwargs["learning_starts"] + warmup)
    env, buffer = model.get_env(), model.replay_buffer
    assert env is not None and buffer is not None
    obs = env.reset()
    actions = np.stack([env.action_space.sample()])
    new_obs, rewards, dones, infos = env.step(actions)
    batch_size = case.kwargs["batch_size"]
    parts = dict(
        env_step=ms_per_call(lambda: env.step(actions), device, repeats),
        act=ms_per_call(lambda: model.predict(obs), device, repeats),
        store=ms_per_call(lambda: buffer.add(obs, new_obs, actions, rewards, dones * False, infos), device, repeats),
        sample=ms_per_call(lambda: buffer.sample(batch_size, env=model._vec_normalize_env), device, repeats),
        gradient_step=ms_per_call(lambda: model.train(1, batch_size), device, repeats),
    )
    return dict(case=f"split:{case.name} (ms per call)", **parts)


def side_by_side(n_procs: int, device: str, warmup: int, steps: int) -> dict[str, Any]:
    """``n_procs`` processes of the fast ReacherImage stage at once; their steps/s summed."""
    command = [sys.executable, "-m", "benchmarks.gpu_speed", "--worker", "reacher-image/lean_sac_fast"]
    command += ["--device", device, "--warmup", str(warmup), "--steps", str(steps)]
    start = time.perf_counter()
    procs = [subprocess.Popen(command, stdout=subprocess.PIPE, text=True) for _ in range(n_procs)]
    rates = []
    for proc in procs:
        out, _ = proc.communicate()
        lines = [line for line in out.splitlines() if line.startswith("{")]
        rates.append(json.loads(lines[-1])["steps_per_s"] if proc.returncode == 0 and lines else float("nan"))
    return dict(
        case=f"reacher-image/lean_sac_fast x{n_procs} processes",
        steps_per_s=round(float(np.sum(rates)), 1),
        per_process=rates,
        case_seconds=round(time.perf_counter() - start, 1),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--steps", type=int, default=500, help="timed env steps per case")
    parser.add_argument("--warmup", type=int, default=100, help="training steps before timing (capture included)")
    parser.add_argument("--procs", type=int, default=4, help="fast pixel processes side by side (0: none)")
    parser.add_argument("--only", nargs="*", default=None, help="run the cases whose name contains one of these")
    parser.add_argument("--no-split", action="store_true", help="skip the time split of the pixel step")
    parser.add_argument("--budget-s", type=float, default=170.0, help="skip the cases left after this many seconds")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", default=None, help="folder of gpu_speed.jsonl and gpu_speed.md")
    parser.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    th.set_num_threads(args.threads)
    cases = {case.name: case for case in all_cases()}
    if args.worker is not None:
        print(json.dumps(measure(cases[args.worker], args.device, args.warmup, args.steps)), flush=True)
        return

    machine = th.cuda.get_device_name() if args.device.startswith("cuda") else platform.processor() or platform.machine()
    header = dict(
        machine=machine,
        torch=th.__version__,
        mujoco_gl=os.environ.get("MUJOCO_GL"),
        command=" ".join(["python -m benchmarks.gpu_speed", *sys.argv[1:]]),
    )
    print(json.dumps(header), flush=True)
    selected = [case for name, case in cases.items() if not args.only or any(part in name for part in args.only)]
    jobs: list[tuple[str, Callable[[], dict[str, Any]]]] = [
        (case.name, lambda case=case: measure(case, args.device, args.warmup, args.steps)) for case in selected
    ]
    if args.procs > 0:
        jobs.append(("side_by_side", lambda: side_by_side(args.procs, args.device, args.warmup, args.steps)))
    if not args.no_split:
        for name in ("reacher-image/lean_sac", "reacher-image/lean_sac_fast"):
            jobs.append((f"split:{name}", lambda name=name: split(cases[name], args.device, args.warmup)))
    # the goals first, in case the time budget runs out (PRIORITY)
    jobs.sort(key=lambda job: next(rank for rank, prefix in enumerate(PRIORITY) if job[0].startswith(prefix)))
    results, skipped, start = [], [], time.perf_counter()
    for name, job in jobs:
        if time.perf_counter() - start > args.budget_s:
            skipped.append(name)
            continue
        try:
            result = job()
        except Exception as error:  # a failing case is reported, the others run
            result = dict(case=name, error=repr(error))
        results.append(result)
        print(json.dumps(result), flush=True)
        if args.out is not None:  # after each case: a run stopped from outside keeps what it measured
            write(Path(args.out), header, results, skipped)
    if skipped:
        print(json.dumps(dict(skipped=skipped)), flush=True)
        if args.out is not None:
            write(Path(args.out), header, results, skipped)


def write(out: Path, header: dict[str, Any], results: list[dict[str, Any]], skipped: list[str]) -> None:
    """The results as JSON lines and as a Markdown table."""
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "gpu_speed.jsonl", "w") as file:
        for line in (header, *results, *([dict(skipped=skipped)] if skipped else [])):
            file.write(json.dumps(line) + "\n")
    lines = [f"# GPU fast path: {header['machine']}, torch {header['torch']}, MUJOCO_GL={header['mujoco_gl']}", ""]
    lines += [f"`{header['command']}`", "", "| case | env steps/s | notes |", "|---|---:|---|"]
    for result in results:
        notes = {key: value for key, value in result.items() if key not in ("case", "steps_per_s")}
        lines.append(f"| {result['case']} | {result.get('steps_per_s', '')} | {json.dumps(notes)} |")
    if skipped:
        lines += ["", f"Skipped (time budget): {', '.join(skipped)}"]
    (out / "gpu_speed.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
