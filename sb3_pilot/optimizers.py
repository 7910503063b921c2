"""
The optimizer settings that every part of the package shares, the pixel agents (:mod:`sb3_pilot.pixels`) included:
this module imports nothing of the package, so that any module may import it without an arrow running back up.
"""

from typing import Any

import torch as th


def lean_optimizer_kwargs(
    optimizer_class: type[th.optim.Optimizer], optimizer_kwargs: dict[str, Any] | None
) -> dict[str, Any]:
    """
    Optimizer keyword arguments of the lean update: Adam (and AdamW) fused into one kernel per step (``fused=True``)
    unless ``optimizer_kwargs`` sets ``fused`` or ``foreach``; other optimizers keep their arguments.

    :param optimizer_class: the optimizer class
    :param optimizer_kwargs: the user's keyword arguments (None: none)
    """
    optimizer_kwargs = dict(optimizer_kwargs or {})
    if issubclass(optimizer_class, (th.optim.Adam, th.optim.AdamW)) and not {"fused", "foreach"} & set(optimizer_kwargs):
        optimizer_kwargs["fused"] = True
    return optimizer_kwargs
