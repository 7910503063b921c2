"""
The paper's transfer challenges (and maze-car) as runners over the RL Zoo: ``python -m sb3_pilot.experiments.challenges NAME``.

Each challenge chains zoo training runs (``python -m sb3_pilot.experiments.zoo train``), distillation and evaluation stages for
every seed, resumes what already finished, and writes ``<root>/<challenge>/summary.json``. Each stage runs in a
process of its own, up to ``--jobs N`` at once on this machine or as Ray tasks (``--backend ray``).
"""

from sb3_pilot.experiments.challenges.backends import StageFailed
from sb3_pilot.experiments.challenges.controller import ChooseCheckpoint, ControllerEvaluation
from sb3_pilot.experiments.challenges.definitions import (
    BUDGET_CHALLENGES,
    BUDGETS,
    CHALLENGES,
    REUSE_SHIPPED,
    VARIANTS,
    Challenge,
    at_budget,
    challenge_variant,
    only_stages,
)
from sb3_pilot.experiments.challenges.runner import format_table, run_challenge, stage_graph, steps_to
from sb3_pilot.experiments.challenges.stages import Budget, Distill, Shipped, ZooTrain

__all__ = [
    "BUDGETS",
    "BUDGET_CHALLENGES",
    "CHALLENGES",
    "REUSE_SHIPPED",
    "VARIANTS",
    "Budget",
    "Challenge",
    "ChooseCheckpoint",
    "ControllerEvaluation",
    "Distill",
    "Shipped",
    "StageFailed",
    "ZooTrain",
    "at_budget",
    "challenge_variant",
    "format_table",
    "only_stages",
    "run_challenge",
    "stage_graph",
    "steps_to",
]
