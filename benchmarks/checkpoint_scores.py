"""
Held-out open-ground scores of a controller run's checkpoints, as the zero-shot challenge's ``chosen`` stage scores them
(:meth:`ChooseCheckpoint.score`: 30 deterministic episodes of the controller's own task, reset seed 1000 + seed).

    python -m benchmarks.checkpoint_scores RUN SEED OUT.json STEPS [STEPS ...]

RUN: the zoo's run folder (``.../sac/Pilot-AntLocomotion-v0_1``, holding ``rl_model_<steps>_steps.zip`` and the final
model with its saved settings).
"""

import json
import sys
from pathlib import Path
from types import SimpleNamespace

from sb3_pilot.experiments.challenges.controller import ChooseCheckpoint, training_task
from sb3_pilot.experiments.zoo import register

register()
run, seed, out = Path(sys.argv[1]), int(sys.argv[2]), Path(sys.argv[3])
ctx = SimpleNamespace(seed=seed, steps={}, budget=None)  # the cpu budget: no episode cap, 30 episodes
stage = ChooseCheckpoint("chosen", "controller")
env = training_task(run / "Pilot-AntLocomotion-v0.zip")
scores = {}
for steps in sys.argv[4:]:
    score = stage.score(run / f"rl_model_{steps}_steps.zip", None, env, ctx)
    scores[steps] = {"success": score["success"], "final_distance": score["final_distance"]}
    print(seed, steps, scores[steps], flush=True)
out.write_text(json.dumps(scores, indent=1))
