"""
The teacher of the distillation: any SB3 agent trained on a goal env, loaded from a file if need be, checked before
any work.
"""

from __future__ import annotations

import importlib
import json
import os
import warnings
import zipfile
from pathlib import Path

import torch as th
from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.type_aliases import GymEnv
from stable_baselines3.common.utils import check_for_correct_spaces
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.td3.policies import TD3Policy

from sb3_pilot.common.saved_models import without_replay_buffer
from sb3_pilot.udpo import UDPO

#: What each label needs: ``"rollouts"`` runs any agent's policy; ``"planned"`` reads UDPO's state planner
LABELS = ("rollouts", "planned")
#: The algorithms a teacher file is loaded with, by the module of the policy class it was saved with (DDPG saves a
#: TD3 policy: told apart by its settings, see :func:`load_teacher`)
TEACHER_ALGORITHMS: dict[str, str] = {
    "stable_baselines3.sac.policies": "stable_baselines3:SAC",
    "stable_baselines3.td3.policies": "stable_baselines3:TD3",
    "sb3_contrib.tqc.policies": "sb3_contrib:TQC",
    "sb3_contrib.crossq.policies": "sb3_contrib:CrossQ",
    "sb3_pilot.sac.policies": "sb3_pilot.sac:LeanSAC",
    "sb3_pilot.udpo.policies": "sb3_pilot.udpo:UDPO",
}
#: Standard deviation of the Gaussian noise on the normalised action ([-1, 1]) of a deterministic teacher's rollouts
DETERMINISTIC_TEACHER_NOISE = 0.1


def load_teacher(path: str | os.PathLike, env: GymEnv | None = None, device: th.device | str = "auto") -> BaseAlgorithm:
    """
    Load an SB3 model file (``model.save``'s zip, an RL-Zoo run's ``<env>.zip`` or ``best_model.zip``) with the
    algorithm it was saved by, read from its policy class (:data:`TEACHER_ALGORITHMS`), without its replay buffer
    (the rollouts need none, and a HER buffer could not be built without an env).

    :param path: the model file (``.zip`` may be left out, as SB3's ``load`` allows)
    :param env: the env to roll the teacher out in (with the run's ``VecNormalize`` statistics, if it had any)
    :param device: the device to load it on
    :return: the model
    :raises FileNotFoundError: if there is no such file
    :raises ValueError: if the file is not an SB3 model, or of an algorithm not in :data:`TEACHER_ALGORITHMS`
    """
    path = Path(path)
    if not path.is_file() and path.with_name(path.name + ".zip").is_file():
        path = path.with_name(path.name + ".zip")
    if not path.is_file():
        raise FileNotFoundError(f"No model file at {path}.")
    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(archive.read("data"))
        module = data["policy_class"]["__module__"]
    except (zipfile.BadZipFile, KeyError, TypeError, ValueError) as error:
        raise ValueError(
            f"{path} is not an SB3 model (the zip file that model.save writes, with its 'data'): "
            f"{type(error).__name__}: {error}."
        ) from error
    if module not in TEACHER_ALGORITHMS:
        raise ValueError(
            f"{path} was saved with a policy of {module}, not one of {sorted(TEACHER_ALGORITHMS)}: load it with its "
            "algorithm's load(path, env=...) and pass the model."
        )
    algorithm = TEACHER_ALGORITHMS[module]
    if algorithm.endswith(":TD3") and data.get("policy_delay") == 1 and data.get("target_noise_clip") == 0.0:
        algorithm = "stable_baselines3:DDPG"  # DDPG is TD3 with these settings
    package, name = algorithm.split(":")
    algorithm_class = getattr(importlib.import_module(package), name)
    return algorithm_class.load(path, env=env, device=device, custom_objects=without_replay_buffer())


def is_deterministic(model: BaseAlgorithm) -> bool:
    """Whether the teacher's policy acts deterministically even when asked to sample (TD3's and DDPG's actor)."""
    return isinstance(model.policy, TD3Policy)


def check_teacher(model: BaseAlgorithm, labels: str, env: GymEnv | None) -> None:
    """
    Refuse a teacher that cannot be distilled with ``labels``, naming the problem, before any work: not an SB3 model,
    not trained, not on a goal env, with discrete actions, without an env for the rollouts (or with one of other
    spaces), or another agent than UDPO for labels that read its state planner.

    :param model: the teacher
    :param labels: one of :data:`LABELS`
    :param env: the env of the rollouts (None: the model's)
    """
    if not isinstance(model, BaseAlgorithm):
        raise TypeError(
            f"distill_goal_planner needs an SB3 model (SAC, TD3, DDPG, TQC, LeanSAC, UDPO, ...) or the path of its "
            f"file, got {type(model).__name__}."
        )
    if labels not in LABELS:
        raise ValueError(f"labels must be one of {LABELS}, got {labels!r}.")
    name = type(model).__name__
    obs_space = model.observation_space
    if not isinstance(obs_space, spaces.Dict) or not {"achieved_goal", "desired_goal"} <= set(obs_space.spaces):
        raise ValueError(
            f"distill_goal_planner needs a teacher trained on a goal env (Dict observation with 'achieved_goal' and "
            f"'desired_goal', the target goal g_target), but the {name} teacher's observation space is {obs_space}."
        )
    if not isinstance(model.action_space, spaces.Box):
        raise ValueError(
            f"distill_goal_planner needs a teacher with continuous (Box) actions, but the {name} teacher's action space "
            f"is {model.action_space}: PILoT's planners serve continuous-control agents."
        )
    if labels == "planned" and not isinstance(model, UDPO):
        raise ValueError(
            f"labels='planned' reads UDPO's state planner h(s' | s, g), which a {name} teacher does not have: "
            "use labels='rollouts' (the default), the next goals its own steps reach."
        )
    if model.num_timesteps == 0:
        raise ValueError(
            f"distill_goal_planner needs a trained teacher, but the {name} model has taken 0 env steps "
            "(num_timesteps=0): call model.learn(...) first, or load a trained model."
        )
    if labels == "rollouts" and env is None and model.get_env() is None:
        raise ValueError(
            f"labels='rollouts' runs the {name} teacher in an env, and it has none (a model loaded without env=): "
            "pass env=, with the VecNormalize statistics it was trained with, if any."
        )
    if labels == "rollouts" and env is not None:
        try:
            venv = env if isinstance(env, VecEnv) else model._wrap_env(env)  # images transposed as SB3 does
            check_for_correct_spaces(venv, model.observation_space, model.action_space)
        except ValueError as error:
            raise ValueError(f"The env of the rollouts does not fit the {name} teacher: {error}") from error
    if getattr(model, "_n_updates", None) == 0:
        learning_starts = getattr(model, "learning_starts", "?")
        warnings.warn(
            f"The {name} teacher has taken {model.num_timesteps} env steps but no gradient step (learning_starts="
            f"{learning_starts}): its networks are still their random initialisation, and so will the distilled "
            "planner's landmarks be.",
            stacklevel=3,
        )
