"""Small helpers shared by the stages: naming a task, checking numeric arguments (:mod:`sb3_pilot.checks`)."""

import gymnasium as gym
from stable_baselines3.common.vec_env import VecEnv

from sb3_pilot.checks import check_number

__all__ = ["check_number", "task_id"]


def task_id(env: gym.Env | VecEnv) -> str:
    """
    Name of the task an env (or the first env of a ``VecEnv``) runs: its Gymnasium ID, or the class name of the
    unwrapped env when it was not made with ``gym.make``.

    :param env: a Gymnasium env or an SB3 ``VecEnv``
    """
    if isinstance(env, VecEnv):
        spec = env.get_attr("spec", indices=[0])[0]
        return spec.id if spec is not None else type(env.get_attr("unwrapped", indices=[0])[0]).__name__
    return env.spec.id if env.spec is not None else type(env.unwrapped).__name__
