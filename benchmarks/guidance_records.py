"""
The per-seed records of a challenge's controller stages, small enough to commit (the models are not): each seed's
checkpoint choice (``choice_seed_<k>.json``, its ``chosen/choice.json``), its planner's held-out report
(``distill_seed_<k>.json``, the ``distill`` stage's ``distill.json``: landmark distance and NLL against an untrained
planner's, a teacher step) and its evaluations
(``evaluations_seed_<k>.json``): per episode the success and the final distance to the goal, and for a guided one its
length in steps and how far the agent moved in its last 200 steps (0: it stopped: a fall, a wall or a parked landmark),
the paths left out.

Usage (repository root)::

    python -m benchmarks.guidance_records zoo_runs/pointmaze-to-antmaze-hrl --seeds 0 1 \\
        --stages pilot pilot_switch unguided open_ground
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np

#: The last steps of a guided episode over which its movement is measured.
LAST_STEPS = 200


def stage_record(guidance: dict[str, Any]) -> dict[str, Any]:
    """
    :param guidance: a controller evaluation's ``guidance.json``
    :return: its per-episode successes and final distances, ``horizon`` and ``switch_distance`` where guided, and for
        guided episodes their ``steps`` and ``moved_last_200``
    """
    record = {key: guidance[key] for key in ("successes", "final_distances", "horizon", "switch_distance") if key in guidance}
    paths = [np.asarray(episode["achieved_goals"]) for episode in guidance["episodes"] if "achieved_goals" in episode]
    if paths:
        record["steps"] = [len(path) - 1 for path in paths]
        record[f"moved_last_{LAST_STEPS}"] = [
            float(np.linalg.norm(path[-1] - path[-LAST_STEPS - 1])) if len(path) > LAST_STEPS else None for path in paths
        ]
    return record


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.guidance_records", description=__doc__)
    parser.add_argument("folder", type=Path, help="the challenge's folder (<root>/<challenge>)")
    parser.add_argument("--seeds", type=int, nargs="+", required=True)
    parser.add_argument("--stages", nargs="+", required=True, help="its controller evaluation stages")
    parser.add_argument("--choice", default="chosen", help="the checkpoint choice's stage")
    parser.add_argument("--distill", default="distill", help="the planner's distillation stage")
    args = parser.parse_args()
    for seed in args.seeds:
        models = args.folder / "models" / f"seed_{seed}"
        shutil.copyfile(models / args.choice / "choice.json", args.folder / f"choice_seed_{seed}.json")
        shutil.copyfile(models / args.distill / "distill.json", args.folder / f"distill_seed_{seed}.json")
        records = {stage: stage_record(json.loads((models / stage / "guidance.json").read_text())) for stage in args.stages}
        (args.folder / f"evaluations_seed_{seed}.json").write_text(json.dumps(records, indent=1))
        print(f"seed {seed}:", ", ".join(f"{stage} {np.mean(record['successes']):.2f}" for stage, record in records.items()))


if __name__ == "__main__":
    main()
