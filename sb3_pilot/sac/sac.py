"""SB3's SAC with the lean update (:mod:`sb3_pilot.common.lean`): same algorithm, same numbers, fewer kernels."""

from typing import Any, ClassVar

import torch as th
from stable_baselines3 import SAC
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.noise import ActionNoise
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import DictReplayBufferSamples, GymEnv, PyTorchObs, ReplayBufferSamples, Schedule
from stable_baselines3.sac import policies as sac_policies

from sb3_pilot.common.cuda_graph import CudaGraphUpdate
from sb3_pilot.common.distributions import reparameterised_log_prob
from sb3_pilot.common.lean import LeanSACSteps, LossRecorder, check_update_settings
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
    is not an ensemble) work too, with the other cuts. A policy with the lean step's hooks
    (:class:`~sb3_pilot.common.lean.StepHooks`) takes part in each gradient step: with
    :class:`~sb3_pilot.pixels.PixelGoalSACPolicy` the batch's observations go through the shared encoder once per
    gradient step, as in DrQ-v2 (SB3's ``SAC`` encodes them three times): the actor and the actor's loss read the
    critic's features, detached, from before the critic's update; 3 encoder passes a step instead of 5.

    :param policy: ``"MlpPolicy"``, ``"CnnPolicy"``, ``"MultiInputPolicy"`` or a ``SACPolicy`` class
    :param env: the environment to learn from (a Gymnasium ID, an env or a VecEnv)
    :param learning_rate: learning rate of the actor, the critics and the temperature (a float, or a schedule of the
        progress remaining, from 1 to 0)
    :param buffer_size: size of the replay buffer (>= 1)
    :param learning_starts: env steps of uniform random actions before learning starts
    :param batch_size: minibatch size of each gradient step (>= 1)
    :param tau: the soft (Polyak) update coefficient of the target critics, in [0, 1]
    :param gamma: the discount factor, in [0, 1]
    :param train_freq: update the model every ``train_freq`` steps (or a tuple such as ``(5, "episode")``)
    :param gradient_steps: gradient steps after each rollout (-1: as many as env steps collected)
    :param action_noise: noise added to the actions while collecting (None: the policy's own sampling)
    :param replay_buffer_class: the replay buffer class (e.g. ``HerReplayBuffer``; None: SB3's default)
    :param replay_buffer_kwargs: keyword arguments of the replay buffer
    :param optimize_memory_usage: the memory-efficient variant of the replay buffer
    :param n_steps: n-step returns (1: one-step TD targets)
    :param ent_coef: the temperature ``alpha``: a float, or ``"auto"`` (``"auto_0.1"``: from 0.1) to learn it
    :param target_update_interval: gradient steps between two updates of the target critics
    :param target_entropy: the entropy the learnt temperature aims at (``"auto"``: ``-dim(action)``)
    :param use_sde: generalised State-Dependent Exploration instead of independent Gaussian noise
    :param sde_sample_freq: env steps between two draws of the gSDE noise matrix (-1: once per rollout)
    :param use_sde_at_warmup: use gSDE instead of uniform random actions before learning starts
    :param stats_window_size: episodes averaged in the rollout logs
    :param tensorboard_log: the TensorBoard log folder (None: no TensorBoard)
    :param policy_kwargs: keyword arguments of the policy (``net_arch``, ``n_critics``, ...)
    :param verbose: 0 no output, 1 info, 2 debug
    :param seed: seed of the random generators
    :param device: the device the networks run on (``"auto"``: CUDA if available)
    :param cuda_graphs: on CUDA, capture the gradient step (critic, actor, temperature, target update) as CUDA graphs
        and replay them (:mod:`sb3_pilot.common.cuda_graph`; with ``replay_buffer_kwargs=dict(storage="device")`` the
        HER draw is in the graph too). It changes the random streams; losses are logged as means since the last log
        dump. gSDE, n-step returns or a model off CUDA fall back to the eager step with a warning
    :param _init_setup_model: whether to build the networks at creation
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {
        "MlpPolicy": MlpPolicy,
        "CnnPolicy": CnnPolicy,
        "MultiInputPolicy": MultiInputPolicy,
    }

    def __init__(
        self,
        policy: str | type[sac_policies.SACPolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule = 3e-4,
        buffer_size: int = 1_000_000,
        learning_starts: int = 100,
        batch_size: int = 256,
        tau: float = 0.005,
        gamma: float = 0.99,
        train_freq: int | tuple[int, str] = 1,
        gradient_steps: int = 1,
        action_noise: ActionNoise | None = None,
        replay_buffer_class: type[ReplayBuffer] | None = None,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        optimize_memory_usage: bool = False,
        n_steps: int = 1,
        ent_coef: str | float = "auto",
        target_update_interval: int = 1,
        target_entropy: str | float = "auto",
        use_sde: bool = False,
        sde_sample_freq: int = -1,
        use_sde_at_warmup: bool = False,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        cuda_graphs: bool = False,
        _init_setup_model: bool = True,
    ):
        check_update_settings(buffer_size, batch_size, tau, gamma)
        self.cuda_graphs = cuda_graphs
        super().__init__(
            policy,
            env,
            learning_rate=learning_rate,
            buffer_size=buffer_size,
            learning_starts=learning_starts,
            batch_size=batch_size,
            tau=tau,
            gamma=gamma,
            train_freq=train_freq,
            gradient_steps=gradient_steps,
            action_noise=action_noise,
            replay_buffer_class=replay_buffer_class,
            replay_buffer_kwargs=replay_buffer_kwargs,
            optimize_memory_usage=optimize_memory_usage,
            n_steps=n_steps,
            ent_coef=ent_coef,
            target_update_interval=target_update_interval,
            target_entropy=target_entropy,
            use_sde=use_sde,
            sde_sample_freq=sde_sample_freq,
            use_sde_at_warmup=use_sde_at_warmup,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            policy_kwargs=policy_kwargs,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=_init_setup_model,
        )

    def _setup_model(self) -> None:
        # here rather than in __init__: SB3's load() sets the saved policy class after __init__
        self.policy_class = LEAN_POLICIES.get(self.policy_class, self.policy_class)
        self._use_lean_her()
        super()._setup_model()
        self._attach_step_hooks()
        self._cuda_graph_update = CudaGraphUpdate.for_model(self, self._optimizers()) if self.cuda_graphs else None

    def _optimizers(self) -> list[th.optim.Optimizer]:
        """The optimizers of a gradient step: the actor's, the critics' and the temperature's (if learnt)."""
        optimizers = [self.actor.optimizer, self.critic.optimizer]
        if self.ent_coef_optimizer is not None:
            optimizers.append(self.ent_coef_optimizer)
        return optimizers

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
        self._update_learning_rate(self._optimizers())
        self._run_gradient_steps(gradient_steps, batch_size)
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")

    def _gradient_step(self, replay_data: DictReplayBufferSamples | ReplayBufferSamples, losses: LossRecorder) -> None:
        """
        One step of the temperature, the critics and the actor on a batch (the target update excluded): pure tensor
        code, without host reads, which a CUDA graph captures (``cuda_graphs=True``).

        :param replay_data: the batch
        :param losses: where the losses are logged (a :class:`~sb3_pilot.common.lean.LossRecorder`, or the device sums
            of a captured step)
        """
        if self.use_sde:  # a new noise matrix per step (gSDE is never captured)
            self.actor.reset_noise()
        # the policy's encoding of s, once (a pixel policy's phi(s), DrQ-v2): trained by the critic's loss below, read
        # detached by the actor and its loss
        observations = self._encode(replay_data.observations)
        # Action by the current actor for the sampled states
        actions_pi, log_prob = self.action_log_prob(observations)
        log_prob = log_prob.reshape(-1, 1)

        # Entropy coefficient (temperature) loss
        ent_coef = self._entropy_coef_step(log_prob, losses)

        # Critic loss: 1/2 sum_i (Q_i(s, a) - y)^2, y = r + gamma (1 - d) (min_i Q'_i(s', a') - alpha log pi(a' | s'))
        with th.no_grad():
            # s' as the policy has the actor and the target read it (itself, or a pixel policy's shared features)
            next_observations = self._encode_next(replay_data.next_observations)
            next_actions, next_log_prob = self.action_log_prob(next_observations)
        target_q_values = self._target_q_values(replay_data, next_actions, next_log_prob, ent_coef, next_observations)
        self._critic_step(observations, replay_data.actions, target_q_values, losses)

        # Actor loss: E[alpha log pi(a | s) - min_i Q_i(s, a)], gradients for the actor's parameters only
        actor_loss = self._actor_loss(observations, actions_pi, log_prob, ent_coef, losses)
        self.actor.optimizer.zero_grad()
        actor_loss.backward(inputs=self._actor_parameters)
        self.actor.optimizer.step()

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_actor_parameters"]
