"""
Twin (or n) Q critics as one ensemble: every layer of the ``n_critics`` networks is one batched matrix product
(``th.baddbmm``) over stacked weights, so a forward or backward pass costs one chain of kernels for all critics
instead of one chain per critic. Same function, same initialisation and same interface as SB3's ``ContinuousCritic``.
"""

import itertools
import math
from typing import Any

import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BaseModel
from stable_baselines3.common.preprocessing import get_action_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.type_aliases import PyTorchObs
from torch import nn

#: Name of the ensemble's layers in its state dict (SB3's ``ContinuousCritic`` names them ``qf0.0``, ``qf1.0``, ...).
Q_NETWORKS = "q_networks"


class EnsembleLinear(nn.Module):
    """
    ``n`` independent linear layers applied at once: ``y_i = x_i W_i + b_i`` for ``i = 1..n`` as one ``th.baddbmm``.
    Each ``W_i`` is initialised as ``nn.Linear`` initialises its weight (uniform in ``+-1/sqrt(in_features)``).

    :param n: number of members
    :param in_features: size of each input sample
    :param out_features: size of each output sample
    """

    def __init__(self, n: int, in_features: int, out_features: int):
        super().__init__()
        self.n = n
        self.in_features = in_features
        self.out_features = out_features
        bound = 1 / math.sqrt(in_features)
        self.weight = nn.Parameter(th.empty(n, in_features, out_features).uniform_(-bound, bound))
        self.bias = nn.Parameter(th.empty(n, 1, out_features).uniform_(-bound, bound))

    def forward(self, inputs: th.Tensor) -> th.Tensor:
        """
        :param inputs: ``(n, batch, in_features)``, or ``(batch, in_features)`` shared by every member
        :return: ``(n, batch, out_features)``
        """
        if inputs.dim() == 2:
            inputs = inputs.expand(self.n, *inputs.shape)
        return th.baddbmm(self.bias, inputs, self.weight)

    def extra_repr(self) -> str:
        return f"n={self.n}, in_features={self.in_features}, out_features={self.out_features}"


class EnsembleCritic(BaseModel):
    """
    SB3's ``ContinuousCritic`` (twin Q-networks ``Q_i(s, a)`` on ``[features(s), a]``) with its ``n_critics`` MLPs held
    as one ensemble of :class:`EnsembleLinear` layers. ``forward`` returns one ``(batch, 1)`` tensor per critic, as
    SB3's critic does, so SB3's ``SAC.train`` runs with it unchanged; :meth:`q_values` returns them stacked.

    State dicts of SB3's critic (``qf0.0.weight``, ...: models saved by sb3-pilot <= 0.2) load into it: they are
    stacked on load (:meth:`stack_sb3_critic_state`).

    :param observation_space: Observation space
    :param action_space: Action space
    :param net_arch: Hidden layer sizes of each Q-network
    :param features_extractor: Network to extract features
    :param features_dim: Number of features
    :param activation_fn: Activation function
    :param normalize_images: Whether to divide images by 255
    :param n_critics: Number of Q-networks
    :param share_features_extractor: Whether the features extractor is shared with the actor (then the critic loss
        does not train it, as in SB3)
    """

    features_extractor: BaseFeaturesExtractor

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        net_arch: list[int],
        features_extractor: BaseFeaturesExtractor,
        features_dim: int,
        activation_fn: type[nn.Module] = nn.ReLU,
        normalize_images: bool = True,
        n_critics: int = 2,
        share_features_extractor: bool = True,
    ):
        super().__init__(
            observation_space, action_space, features_extractor=features_extractor, normalize_images=normalize_images
        )
        self.share_features_extractor = share_features_extractor
        self.n_critics = n_critics
        self.net_arch = net_arch
        sizes = [features_dim + get_action_dim(action_space), *net_arch, 1]
        layers: list[nn.Module] = []
        for in_features, out_features in itertools.pairwise(sizes):
            layers += [EnsembleLinear(n_critics, in_features, out_features), activation_fn()]
        self.add_module(Q_NETWORKS, nn.Sequential(*layers[:-1]))
        self._register_load_state_dict_pre_hook(self._load_sb3_critic_state)

    def q_values(self, obs: PyTorchObs, actions: th.Tensor) -> th.Tensor:
        """
        :param obs: observation batch
        :param actions: action batch, shape ``(batch, action_dim)``
        :return: ``Q_i(s, a)`` of every critic, shape ``(n_critics, batch, 1)``
        """
        with th.set_grad_enabled(th.is_grad_enabled() and not self.share_features_extractor):
            features = self.extract_features(obs, self.features_extractor)
        return self.q_networks(th.cat([features, actions], dim=1))

    def forward(self, obs: PyTorchObs, actions: th.Tensor) -> tuple[th.Tensor, ...]:
        return tuple(self.q_values(obs, actions).unbind(0))

    def q1_forward(self, obs: PyTorchObs, actions: th.Tensor) -> th.Tensor:
        """The first critic's ``Q_1(s, a)`` (as TD3's actor loss uses it), without gradient to the features."""
        with th.no_grad():
            features = self.extract_features(obs, self.features_extractor)
        inputs = th.cat([features, actions], dim=1)
        for layer in self.q_networks:
            inputs = th.addmm(layer.bias[0], inputs, layer.weight[0]) if isinstance(layer, EnsembleLinear) else layer(inputs)
        return inputs

    @staticmethod
    def stack_sb3_critic_state(state_dict: dict[str, Any], prefix: str, n_critics: int) -> bool:
        """
        Rewrite, in place, the Q-networks of an SB3 ``ContinuousCritic`` state dict (``{prefix}qf{i}.{layer}.weight``
        of shape ``(out, in)``) as this ensemble's (``{prefix}q_networks.{layer}.weight``, ``(n, in, out)``).

        :param state_dict: a state dict holding the critic's entries under ``prefix``
        :param prefix: the critic's prefix in it (``"critic."`` in a policy's state dict)
        :param n_critics: number of critics
        :return: whether anything was rewritten
        """
        first = f"{prefix}qf0."
        layers = sorted({key[len(first) :].split(".")[0] for key in state_dict if key.startswith(first)}, key=int)
        for layer in layers:
            weights = [state_dict.pop(f"{prefix}qf{idx}.{layer}.weight") for idx in range(n_critics)]
            biases = [state_dict.pop(f"{prefix}qf{idx}.{layer}.bias") for idx in range(n_critics)]
            state_dict[f"{prefix}{Q_NETWORKS}.{layer}.weight"] = th.stack([weight.T for weight in weights])
            state_dict[f"{prefix}{Q_NETWORKS}.{layer}.bias"] = th.stack(biases).unsqueeze(1)
        return bool(layers)

    def _load_sb3_critic_state(self, state_dict: dict[str, Any], prefix: str, *args: Any) -> None:
        self.stack_sb3_critic_state(state_dict, prefix, self.n_critics)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(net_arch=self.net_arch, n_critics=self.n_critics)
        return data


def stack_sb3_critic_parameters(params: dict[str, dict[str, Any]], n_critics: int) -> None:
    """
    Rewrite, in place, the parameters of a model saved with SB3's ``ContinuousCritic`` (``BaseAlgorithm.get_parameters``
    or a saved zip's: ``policy`` and ``critic.optimizer``) for an :class:`EnsembleCritic`: the critic and target
    weights are stacked, and so are the critic optimizer's per-parameter states (Adam's moments), so that training
    resumes where it stopped. A no-op for parameters saved with the ensemble.

    :param params: the model's parameters, by object name
    :param n_critics: number of critics
    """
    policy = params["policy"]
    if not EnsembleCritic.stack_sb3_critic_state(policy, "critic.", n_critics):
        return
    EnsembleCritic.stack_sb3_critic_state(policy, "critic_target.", n_critics)
    optimizer = params.get("critic.optimizer")
    if optimizer is None:
        return
    (group,) = optimizer["param_groups"]
    n_ensemble = 2 * sum(key.startswith(f"critic.{Q_NETWORKS}.") and key.endswith(".weight") for key in policy)
    n_features = len(group["params"]) - n_critics * n_ensemble  # the features extractor's parameters come first
    state = optimizer["state"]
    stacked_state: dict[int, dict[str, Any]] = {idx: state[idx] for idx in range(n_features) if idx in state}
    for idx in range(n_ensemble):
        members = [state.get(n_features + critic * n_ensemble + idx) for critic in range(n_critics)]
        if any(member is None for member in members):
            continue  # never stepped: no state to carry
        is_weight = idx % 2 == 0
        stacked_state[n_features + idx] = {
            key: members[0][key]
            if key == "step"
            else th.stack([member[key].T if is_weight else member[key].unsqueeze(0) for member in members])
            for key in members[0]
        }
    optimizer["state"] = stacked_state
    group["params"] = list(range(n_features + n_ensemble))
