"""
Sizing of the maze-car pair from SAC+HER alone (run before any HER+PILoT run): the challenge's ``her`` stage only,
at the cpu budget, seeds 0..N-1. Its stages are the full challenge's (same configuration hash), so the challenge
run reuses them.

    OMP_NUM_THREADS=1 python zoo_runs/maze-car/size_her.py 6
"""

import dataclasses
import sys

from sb3_pilot.experiments.challenges import CHALLENGES, run_challenge

challenge = CHALLENGES["maze-car"]
her_only = dataclasses.replace(challenge, stages=tuple(stage for stage in challenge.stages if stage.name == "her"))
run_challenge(her_only, "cpu", seeds=range(int(sys.argv[1])), root="zoo_runs")
