"""Small helpers shared by the stages: naming a task, checking numeric arguments."""

import math
import numbers

import gymnasium as gym
from stable_baselines3.common.vec_env import VecEnv


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


def check_number(
    name: str,
    value: float,
    minimum: float | None = None,
    strict: bool = False,
    integer: bool = False,
    maximum: float | None = None,
) -> None:
    """
    Refuse a numeric argument that is not a finite number (an integer if ``integer``), or lies below ``minimum`` or
    above ``maximum``, with a ``ValueError`` naming it.

    :param name: the argument's name, for the message
    :param value: its value
    :param minimum: the smallest value allowed (None: any finite number)
    :param strict: whether ``minimum`` itself is refused
    :param integer: whether the value must be an integer
    :param maximum: the largest value allowed (None: no bound)
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}.")
    if integer and not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer, got {value!r}.")
    if minimum is not None and (value <= minimum if strict else value < minimum):
        raise ValueError(f"{name} must be {'>' if strict else '>='} {minimum}, got {value!r}.")
    if maximum is not None and value > maximum:
        raise ValueError(f"{name} must be <= {maximum}, got {value!r}.")
