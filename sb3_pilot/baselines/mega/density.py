"""MEGA's density model of achieved goals: a Gaussian kernel density on standardised samples (mrl's RawKernelDensity)."""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

from sb3_pilot.common.utils import check_number

# mrl adds it to the sample's standard deviation, so a constant coordinate does not divide by zero
STD_EPS = 1e-4


def check_finite_goals(name: str, goals: np.ndarray) -> np.ndarray:
    """
    :param name: what the goals are, for the message
    :param goals: goals of shape (n, goal_dim)
    :return: the goals as a float64 array
    """
    goals = np.asarray(goals, dtype=np.float64)
    if goals.ndim != 2:
        raise ValueError(f"{name} must have shape (n, goal_dim), got {goals.shape}.")
    if not np.all(np.isfinite(goals)):
        raise ValueError(f"{name} hold NaN or infinite values: MEGA cannot fit a density to them.")
    return goals


class KernelDensity:
    """
    Gaussian kernel density of goals, fitted on samples standardised by their own mean and standard deviation
    (mrl's ``RawKernelDensity`` with ``normalize=True``; sklearn's ``KernelDensity(kernel="gaussian")`` in numpy).
    Densities are those of the standardised goals: the same ranking as in goal space, and a bandwidth that means the
    same on every task whatever its units or bounds.

    :param bandwidth: kernel standard deviation ``h``, in units of the samples' standard deviation (mrl: 0.1)
    """

    def __init__(self, bandwidth: float = 0.1):
        check_number("bandwidth", bandwidth, minimum=0, strict=True)
        self.bandwidth = bandwidth
        self.mean: np.ndarray | None = None
        self.std: np.ndarray | None = None
        self.samples: np.ndarray | None = None

    def fit(self, samples: np.ndarray) -> KernelDensity:
        """
        :param samples: achieved goals of shape (n, goal_dim), finite
        :return: self
        """
        samples = check_finite_goals("The achieved goals to fit", samples)
        if len(samples) == 0:
            raise ValueError("KernelDensity.fit needs at least one sample.")
        self.mean = samples.mean(axis=0)
        self.std = samples.std(axis=0) + STD_EPS
        self.samples = (samples - self.mean) / self.std
        return self

    def log_density(self, points: np.ndarray) -> np.ndarray:
        """
        ``log p(x) = logsumexp_i(-||x - x_i||^2 / (2 h^2)) - log n - d/2 log(2 pi h^2)`` on standardised goals.

        :param points: goals of shape (m, goal_dim)
        :return: log densities of shape (m,)
        """
        if self.samples is None:
            raise RuntimeError("Call KernelDensity.fit() before log_density().")
        points = (check_finite_goals("The goals to score", points) - self.mean) / self.std
        n, dim = self.samples.shape
        squared = np.sum(points**2, axis=1)[:, None] - 2.0 * points @ self.samples.T + np.sum(self.samples**2, axis=1)[None]
        log_kernels = -np.maximum(squared, 0.0) / (2.0 * self.bandwidth**2)
        return logsumexp(log_kernels, axis=1) - np.log(n) - 0.5 * dim * np.log(2.0 * np.pi * self.bandwidth**2)
