"""
Argument checks that every part of the package shares, the tasks (:mod:`sb3_pilot.envs`) included: this module
imports nothing of the package, so that any module may import it without an arrow running back up.
"""

import math
import numbers


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
