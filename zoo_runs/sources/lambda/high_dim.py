"""
The High-Dim-Action challenge (``high-dim-action``: UDPO on Pilot/FetchReach-v0 -> its state planner, frozen, in a
UDPO on Pilot/FetchReachHighDim-v0, vs SAC + HER) with the *source* UDPO's ``planner_coef`` set to each lambda
(``-params planner_coef:LAMBDA`` on the source stage; the target's planner is frozen, so its own lambda does not
act). Writes ROOT/lambda_<LAMBDA>/high-dim-action/ (summary.json per lambda); SAC + HER does not depend on lambda:
its stage folders are copied from the first lambda's run (same config hash, so the runner reuses them), or it is
left out (``--no-her``).

    OMP_NUM_THREADS=1 MUJOCO_GL=osmesa python zoo_runs/sources/lambda/high_dim.py --budget cpu --seeds 3 \
        --coefs 0.01 0.0 0.001 --root /tmp/lambda/high_dim
"""

import argparse
import dataclasses
import shutil
from pathlib import Path
from typing import Any

from sb3_pilot.experiments.challenges.definitions import CHALLENGES
from sb3_pilot.experiments.challenges.runner import run_challenge


@dataclasses.dataclass(frozen=True)
class PlannerCoef:
    """The source stage's ``-params``: its lambda."""

    value: float

    def __call__(self, outputs: dict[str, Path]) -> dict[str, Any]:
        return {"planner_coef": self.value}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--budget", default="cpu")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--coefs", type=float, nargs="+", default=[1e-2, 0.0, 1e-3])
    parser.add_argument("--root", default="/tmp/lambda/high_dim")
    parser.add_argument("--no-her", action="store_true", help="leave out SAC + HER (it does not depend on lambda)")
    args = parser.parse_args()
    base = CHALLENGES["high-dim-action"]
    first = None
    for coef in args.coefs:
        stages = tuple(
            dataclasses.replace(stage, params=PlannerCoef(coef)) if stage.name == "source" else stage
            for stage in base.stages
            if not (args.no_her and stage.name == "her")
        )
        root = Path(args.root) / f"lambda_{coef:g}"
        if first is not None and not args.no_her:
            for seed in range(args.seeds):
                her = Path(f"models/seed_{seed}/her")
                if not (root / base.name / her).exists():
                    shutil.copytree(first / base.name / her, root / base.name / her)
        run_challenge(dataclasses.replace(base, stages=stages), args.budget, seeds=range(args.seeds), root=root)
        first = first or root


if __name__ == "__main__":
    main()
