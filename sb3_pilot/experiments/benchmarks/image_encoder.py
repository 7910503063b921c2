"""
NatureCNN vs the paper's encoder for the pixel-only agents (:class:`~sb3_pilot.common.torch_layers.PixelGoalSACPolicy`):
SAC + HER on an image task with the Vec-to-Image challenge's settings at the ``cpu`` budget (its ``her`` stage, only
the encoder differs), for a number of env steps; reports wall time, env steps/s, success per evaluation and final
success per wall-clock minute.

    python -m sb3_pilot.experiments.benchmarks.image_encoder [--env Pilot/FetchReachImage-v0] [--steps 4000]
        [--seed 0] [--root /tmp/image_encoder] [--encoders nature paper]

Writes ``<root>/image_encoder.json``; runs resume (a finished run is skipped, through the challenge stages' markers).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch as th

from sb3_pilot.experiments.challenges.definitions import BUDGETS, VEC_TO_IMAGE_FAST
from sb3_pilot.experiments.challenges.stages import StageContext, ZooTrain, run_stage


def main(argv: list[str] | None = None) -> None:
    """Run SAC + HER with each encoder and print the comparison."""
    parser = argparse.ArgumentParser(prog="python -m sb3_pilot.experiments.benchmarks.image_encoder", description=__doc__)
    parser.add_argument("--env", default="Pilot/FetchReachImage-v0")
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--root", default="/tmp/image_encoder")
    parser.add_argument("--encoders", nargs="+", default=["nature", "paper"])
    args = parser.parse_args(argv)
    th.set_num_threads(1)
    results = {}
    for encoder in args.encoders:
        fast = {**VEC_TO_IMAGE_FAST, "sac": {**VEC_TO_IMAGE_FAST["sac"], "policy_kwargs": {}}}
        fast["sac"]["policy_kwargs"] = {"features_extractor_kwargs": {"encoder": encoder}}
        stage = ZooTrain(encoder, "sac", args.env, "sac.yml")
        seed_dir = Path(args.root).resolve() / args.env.replace("/", "-") / "models" / f"seed_{args.seed}"
        ctx = StageContext(seed_dir, args.seed, BUDGETS["cpu"], {encoder: args.steps}, fast)
        marker = run_stage(stage, ctx, {}, f"[{encoder}]")
        timesteps, success = stage.curve(seed_dir / encoder)
        minutes = marker["wall_time_s"] / 60
        results[encoder] = {
            "steps": args.steps,
            "wall_time_s": round(marker["wall_time_s"], 1),
            "steps_per_s": round(args.steps / marker["wall_time_s"], 2),
            "timesteps": timesteps,
            "success_rate": success,
            "final_success": success[-1],
            "final_success_per_minute": round(success[-1] / minutes, 4),
        }
    out = Path(args.root) / "image_encoder.json"
    out.write_text(json.dumps({"env": args.env, "seed": args.seed, "results": results}, indent=1))
    print("| encoder | env steps | wall time (s) | env steps/s | success per evaluation | final success / minute |")
    print("|---|---|---|---|---|---|")
    for encoder, result in results.items():
        rates = " ".join(f"{rate:.1f}" for rate in result["success_rate"])
        print(
            f"| {encoder} | {result['steps']} | {result['wall_time_s']:.0f} | {result['steps_per_s']:.1f} | {rates} | "
            f"{result['final_success_per_minute']:.3f} |"
        )
    print(f"Written to {out}")


if __name__ == "__main__":
    main()
