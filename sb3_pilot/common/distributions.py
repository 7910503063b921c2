"""Gaussian log-likelihoods of the state planner, the inverse dynamics, the decoupled policy and the goal planner."""

import math
from collections.abc import Callable

import torch as th
from torch.nn import functional as F

# Same bounds as SB3's SAC actor
LOG_STD_MAX = 2
LOG_STD_MIN = -20
_HALF_LOG_2PI = 0.5 * math.log(2 * math.pi)


def gaussian_log_prob(value: th.Tensor, mean: th.Tensor, log_std: th.Tensor) -> th.Tensor:
    """
    Log-density of a diagonal Gaussian, summed over the last dimension.

    :param value: points, shape (..., dim)
    :param mean: means, same shape
    :param log_std: log standard deviations, same shape
    :return: log-densities, shape (...)
    """
    return -(0.5 * ((value - mean) * th.exp(-log_std)) ** 2 + log_std + _HALF_LOG_2PI).sum(dim=-1)


def gaussian_expected_nll(mean: th.Tensor, std: th.Tensor, model_mean: th.Tensor, model_log_std: th.Tensor) -> th.Tensor:
    """
    Expected negative log-likelihood ``E_{x ~ N(mean, std)} [-log N(x | model_mean, exp(model_log_std))]`` in closed
    form (a cross-entropy of diagonal Gaussians), summed over the last dimension.

    :param mean: mean of the data distribution, shape (..., dim)
    :param std: its standard deviation, same shape
    :param model_mean: mean of the model, same shape
    :param model_log_std: log standard deviation of the model, same shape
    :return: expected NLL, shape (...)
    """
    return -gaussian_log_prob(mean, model_mean, model_log_std) + 0.5 * ((std * th.exp(-model_log_std)) ** 2).sum(dim=-1)


def multivariate_gaussian_log_prob(value: th.Tensor, covariance: th.Tensor) -> th.Tensor:
    """
    Log-density of a zero-mean Gaussian with a full covariance, through its Cholesky factor.

    :param value: points, shape (batch, dim)
    :param covariance: symmetric positive-definite matrices, shape (batch, dim, dim)
    :return: log-densities, shape (batch,)
    """
    cholesky = th.linalg.cholesky(covariance)
    whitened = th.linalg.solve_triangular(cholesky, value.unsqueeze(-1), upper=False).squeeze(-1)
    log_det = th.log(th.diagonal(cholesky, dim1=-2, dim2=-1)).sum(dim=-1)
    return -0.5 * (whitened**2).sum(dim=-1) - log_det - value.shape[-1] * _HALF_LOG_2PI


def squashed_gaussian_log_prob(gaussian: th.Tensor, mean: th.Tensor, log_std: th.Tensor) -> th.Tensor:
    """
    Log-probability of ``tanh(gaussian)`` for ``gaussian ~ N(mean, exp(log_std))``, summed over the last dimension.

    :param gaussian: pre-squash values, shape (..., dim)
    :param mean: mean of the pre-squash Gaussian, same shape
    :param log_std: its log standard deviation, same shape
    :return: log-probabilities, shape (...)
    """
    return gaussian_log_prob(gaussian, mean, log_std) - tanh_log_det(gaussian)


def tanh_log_det(gaussian: th.Tensor) -> th.Tensor:
    """``sum log(1 - tanh(u)^2)`` over the last dimension, computed stably as ``2 (log 2 - u - softplus(-2u))``."""
    return (2 * (math.log(2) - gaussian - F.softplus(-2 * gaussian))).sum(dim=-1)


def reparameterised_log_prob(noise: th.Tensor, log_std: th.Tensor) -> th.Tensor:
    """
    Log-density of a reparameterised diagonal Gaussian sample ``mean + exp(log_std) * noise``, summed over the last
    dimension: ``gaussian_log_prob`` at that sample, from the noise itself (``(x - mean) / std = noise``).

    :param noise: the standard normal draws, shape (..., dim)
    :param log_std: log standard deviations, same shape
    :return: log-densities, shape (...)
    """
    return (-0.5 * noise**2 - log_std - _HALF_LOG_2PI).sum(dim=-1)


def squashed_gaussian_sample(
    mean: th.Tensor,
    log_std: th.Tensor,
    deterministic: bool = False,
    pre_squash_log_prob: Callable[[th.Tensor, th.Tensor], th.Tensor] = reparameterised_log_prob,
) -> tuple[th.Tensor, th.Tensor]:
    """
    Reparameterised sample of ``tanh(u)``, ``u ~ N(mean, exp(log_std))``, and its log-probability.

    :param mean: mean of the pre-squash Gaussian
    :param log_std: log standard deviation of the pre-squash Gaussian
    :param deterministic: return ``tanh(mean)`` instead of a sample (its log-probability is then the diagonal
        Gaussian's, whatever ``pre_squash_log_prob``)
    :param pre_squash_log_prob: the log-density of ``u`` from its standard normal draw and ``log_std``; the diagonal
        Gaussian's by default, UDPO's linearised policy density for ``entropy_term="linearised"``
    :return: the squashed sample and its log-probability (shape ``(batch,)``)
    """
    if deterministic:
        return th.tanh(mean), squashed_gaussian_log_prob(mean, mean, log_std)
    noise = th.randn_like(mean)
    gaussian = mean + noise * th.exp(log_std)
    return th.tanh(gaussian), pre_squash_log_prob(noise, log_std) - tanh_log_det(gaussian)
