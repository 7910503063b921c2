"""
What this package adds to the RL Zoo through the zoo's public surface: its algorithms in ``rl_zoo3.ALGOS`` (UDPO as
``udpo``, :class:`~sb3_pilot.sac.LeanSAC` as ``lean_sac``) with their ``--optimize`` samplers, its tasks in Gymnasium's
registry (the ``Pilot/`` tasks and gymnasium-robotics'), as the RL-Zoo docs do for SBX, and its YAML folder
(:func:`hyperparams_dir`). What the zoo has no hook for is in :mod:`sb3_pilot.experiments.zoo_shim`.
"""

from __future__ import annotations

import site
import sysconfig
from pathlib import Path
from typing import Any

import gymnasium as gym
import optuna

from sb3_pilot.envs import register_envs
from sb3_pilot.sac import LeanSAC
from sb3_pilot.udpo import UDPO

#: Zoo algorithms of this package that read another algorithm's YAML (``--algo lean_sac`` reads ``sac.yml``).
CONF_OF = {"lean_sac": "sac"}
#: The paper's UDPO search grid (appendix, "Important Hyperparameters"): ``lambda`` and ``Delta``.
PLANNER_COEF_GRID = (1e-3, 5e-3, 1e-2, 5e-2, 1e-1)
INVERSE_DYNAMICS_INTERVAL_GRID = (200, 500, 1500, 2000)


def hyperparams_dir() -> Path:
    """
    The package's RL-Zoo YAML folder: ``hyperparams/`` of the source checkout (editable install), else the copy a
    wheel installs under ``<prefix>/share/sb3_pilot/hyperparams`` (setup.cfg ``data_files``).
    """
    share = Path("share", "sb3_pilot", "hyperparams")
    candidates = [
        Path(__file__).resolve().parents[2] / "hyperparams",
        Path(sysconfig.get_path("data")) / share,
        Path(site.getuserbase()) / share,
    ]
    for candidate in candidates:
        if (candidate / "udpo.yml").is_file():
            return candidate
    raise FileNotFoundError(f"sb3_pilot's hyperparams/ folder was not found in {[str(path) for path in candidates]}.")


def sample_udpo_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict[str, Any]) -> dict[str, Any]:
    """``--optimize`` sampler for UDPO: the zoo's SAC sampler plus the paper's grid for ``lambda`` and ``Delta``."""
    from rl_zoo3.hyperparams_opt import sample_sac_params

    hyperparams = sample_sac_params(trial, n_actions, n_envs, additional_args)
    hyperparams["planner_coef"] = trial.suggest_categorical("planner_coef", PLANNER_COEF_GRID)
    hyperparams["inverse_dynamics_interval"] = trial.suggest_categorical(
        "inverse_dynamics_interval", INVERSE_DYNAMICS_INTERVAL_GRID
    )
    return hyperparams


def register() -> None:
    """
    Register the ``Pilot/`` tasks and gymnasium-robotics' tasks (whose own IDs ``hyperparams/`` also covers), UDPO as
    the zoo's ``udpo`` and :class:`~sb3_pilot.sac.LeanSAC` as ``lean_sac`` (model class, ``--optimize`` sampler and
    converter: ``rl_zoo3.ALGOS``, ``HYPERPARAMS_SAMPLER``, ``HYPERPARAMS_CONVERTER``). Safe to call again.
    """
    import gymnasium_robotics
    from rl_zoo3 import ALGOS
    from rl_zoo3.hyperparams_opt import (
        HYPERPARAMS_CONVERTER,
        HYPERPARAMS_SAMPLER,
        convert_offpolicy_params,
        sample_sac_params,
    )

    register_envs()
    gym.register_envs(gymnasium_robotics)
    ALGOS["udpo"] = UDPO
    HYPERPARAMS_SAMPLER["udpo"] = sample_udpo_params
    HYPERPARAMS_CONVERTER["udpo"] = convert_offpolicy_params
    ALGOS["lean_sac"] = LeanSAC
    HYPERPARAMS_SAMPLER["lean_sac"] = sample_sac_params
    HYPERPARAMS_CONVERTER["lean_sac"] = convert_offpolicy_params
