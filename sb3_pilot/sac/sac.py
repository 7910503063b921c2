"""SB3's SAC with the lean update (:mod:`sb3_pilot.common.lean`): same algorithm, same numbers, fewer kernels."""

from typing import Any, ClassVar

import torch as th
from stable_baselines3 import SAC
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import PyTorchObs
from stable_baselines3.sac import policies as sac_policies

from sb3_pilot.common.distributions import reparameterised_log_prob
from sb3_pilot.common.lean import LeanSACSteps, LossRecorder, q_values
from sb3_pilot.sac.policies import CnnPolicy, LeanSACPolicy, MlpPolicy, MultiInputPolicy

#: SB3's SAC policy classes and their lean twins
LEAN_POLICIES: dict[Any, type[LeanSACPolicy]] = {
    sac_policies.SACPolicy: MlpPolicy,
    sac_policies.CnnPolicy: CnnPolicy,
    sac_policies.MultiInputPolicy: MultiInputPolicy,
}
#: SB3's ``SquashedDiagGaussianDistribution`` epsilon in ``log(1 - tanh(u)^2 + epsilon)``
SB3_SQUASH_EPSILON = 1e-6


class LeanSAC(LeanSACSteps, SAC):
    """
    Soft Actor-Critic (Haarnoja et al., 2018) as SB3's ``SAC`` (same arguments, losses, saving, RL-Zoo and callbacks),
    with a lean gradient step: the twin critics as one ensemble (:class:`~sb3_pilot.common.critics.EnsembleCritic`),
    fused Adam, the actor's action and log-probability computed without ``torch.distributions`` objects, gradients of
    the actor loss computed for the actor only, one ``foreach`` target update and no host read per step (the losses
    are read once per ``train()`` call). The numbers of each step are SB3's up to float rounding (tested).

    SB3's ``HerReplayBuffer`` is replaced by :class:`~sb3_pilot.common.buffers.LeanHerReplayBuffer` (same samples),
    and SB3's own SAC policy classes by their lean twins (:mod:`sb3_pilot.sac.policies`), so models saved by
    SB3's ``SAC`` load into it (their twin critics are stacked on load). Other ``SACPolicy`` subclasses (whose critic
    is not an ensemble) work too, with the other cuts.

    :param args: positional arguments of SB3's ``SAC`` (``policy``, ``env``, ``learning_rate``, ...)
    :param kwargs: keyword arguments of SB3's ``SAC``
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {
        "MlpPolicy": MlpPolicy,
        "CnnPolicy": CnnPolicy,
        "MultiInputPolicy": MultiInputPolicy,
    }

    def _setup_model(self) -> None:
        # here rather than in __init__: SB3's load() sets the saved policy class after __init__
        self.policy_class = LEAN_POLICIES.get(self.policy_class, self.policy_class)
        self._use_lean_her()
        super()._setup_model()

    def _create_aliases(self) -> None:
        super()._create_aliases()
        self._actor_parameters = list(self.actor.parameters())
        self._critic_parameters = list(self.critic.parameters())
        self._critic_target_parameters = list(self.critic_target.parameters())

    def action_log_prob(self, observations: PyTorchObs) -> tuple[th.Tensor, th.Tensor]:
        """
        The actor's reparameterised action ``a = tanh(mu + sigma eps)`` and ``log pi(a | s)``: SB3's
        ``Actor.action_log_prob`` (same random draws, same formula) without building ``torch.distributions`` objects.

        :param observations: observation batch
        :return: actions in ``[-1, 1]`` and their log-probabilities, shape ``(batch,)``
        """
        if self.use_sde:
            return self.actor.action_log_prob(observations)
        mean_actions, log_std, _ = self.actor.get_action_dist_params(observations)
        noise = th.randn_like(mean_actions)
        actions = th.tanh(mean_actions + noise * th.exp(log_std))
        log_prob = reparameterised_log_prob(noise, log_std)
        return actions, log_prob - th.log(1 - actions**2 + SB3_SQUASH_EPSILON).sum(dim=1)

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        self.policy.set_training_mode(True)
        optimizers = [self.actor.optimizer, self.critic.optimizer]
        if self.ent_coef_optimizer is not None:
            optimizers.append(self.ent_coef_optimizer)
        self._update_learning_rate(optimizers)
        losses = LossRecorder()

        for gradient_step in range(gradient_steps):
            replay_data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            discounts = replay_data.discounts if replay_data.discounts is not None else self.gamma
            if self.use_sde:
                self.actor.reset_noise()

            # Action by the current actor for the sampled states
            actions_pi, log_prob = self.action_log_prob(replay_data.observations)
            log_prob = log_prob.reshape(-1, 1)

            # Entropy coefficient (temperature) loss
            ent_coef = self._entropy_coef_step(log_prob, losses)

            # Critic loss: 1/2 sum_i (Q_i(s, a) - y)^2, y = r + gamma (1 - d) (min_i Q'_i(s', a') - alpha log pi(a' | s'))
            with th.no_grad():
                next_actions, next_log_prob = self.action_log_prob(replay_data.next_observations)
                next_q_values = q_values(self.critic_target, replay_data.next_observations, next_actions).amin(dim=0)
                next_q_values = next_q_values - ent_coef * next_log_prob.reshape(-1, 1)
                target_q_values = replay_data.rewards + (1 - replay_data.dones) * discounts * next_q_values
            self._critic_step(replay_data.observations, replay_data.actions, target_q_values, losses)

            # Actor loss: E[alpha log pi(a | s) - min_i Q_i(s, a)], gradients for the actor's parameters only
            min_qf_pi = q_values(self.critic, replay_data.observations, actions_pi).amin(dim=0)
            actor_loss = (ent_coef * log_prob - min_qf_pi).mean()
            losses.add("actor_loss", actor_loss)
            self.actor.optimizer.zero_grad()
            actor_loss.backward(inputs=self._actor_parameters)
            self.actor.optimizer.step()

            self._update_target_critics(gradient_step)

        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        losses.record(self.logger)

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_actor_parameters"]
