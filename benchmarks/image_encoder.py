"""
NatureCNN vs the paper's encoder for the pixel-only agents (:class:`~sb3_pilot.common.PixelGoalSACPolicy`):
SAC + HER on an image task with the Vec-to-Image challenge's settings at the ``cpu`` budget (its ``her`` stage, only
the encoder differs), for a number of env steps; reports wall time, env steps/s, success per evaluation and final
success per wall-clock minute.

    python -m benchmarks.image_encoder [--env Pilot/FetchReachImage-v0] [--steps 4000]
        [--seed 0] [--root runs/image_encoder] [--encoders nature paper]

Writes ``<root>/image_encoder.json`` (and the challenge runner's ``<root>/image-encoder/``); runs resume (a finished
run is skipped, through the challenge stages' markers).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch as th

from sb3_pilot.experiments.challenges import Challenge, ZooTrain, run_challenge


@dataclass(frozen=True)
class Encoder:
    """A stage's ``-params``: the pixel policy's encoder."""

    name: str

    def __call__(self, outputs: dict[str, Path]) -> dict[str, Any]:
        return {"policy_kwargs": {"features_extractor_kwargs": {"encoder": self.name}}}


def encoder_challenge(env_id: str, encoders: list[str], steps: int) -> Challenge:
    """SAC + HER on ``env_id`` once per encoder, with the Vec-to-Image challenge's ``her`` stage settings."""
    stages = tuple(
        ZooTrain(encoder, "sac", env_id, "sac.yml", params=Encoder(encoder), method=f"SAC+HER ({encoder} encoder)")
        for encoder in encoders
    )
    return Challenge(
        "image-encoder",
        f"SAC + HER on {env_id} with each image encoder",
        env_id,
        stages,
        steps={"cpu": dict.fromkeys(encoders, steps)},
        recipe="vec_to_image_reacher" if env_id == "Pilot/ReacherImage-v0" else "vec_to_image",
    )


def main(argv: list[str] | None = None) -> None:
    """Run SAC + HER with each encoder and print the comparison."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.image_encoder", description=__doc__)
    parser.add_argument("--env", default="Pilot/FetchReachImage-v0")
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--root", default="runs/image_encoder")
    parser.add_argument("--encoders", nargs="+", default=["nature", "paper"])
    args = parser.parse_args(argv)
    th.set_num_threads(1)
    summary = run_challenge(encoder_challenge(args.env, args.encoders, args.steps), "cpu", seeds=[args.seed], root=args.root)
    results = {}
    for encoder in args.encoders:
        (run,) = summary["methods"][f"SAC+HER ({encoder} encoder)"]["runs"]
        wall_time = summary["stages"][f"seed_{args.seed}/{encoder}"]["wall_time_s"]
        timesteps, success = run["timesteps"], run["success_rate"]
        results[encoder] = {
            "steps": args.steps,
            "wall_time_s": round(wall_time, 1),
            "steps_per_s": round(args.steps / wall_time, 2),
            "timesteps": timesteps,
            "success_rate": success,
            "final_success": success[-1],
            "final_success_per_minute": round(success[-1] / (wall_time / 60), 4),
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
