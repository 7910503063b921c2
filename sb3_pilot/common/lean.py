"""
The lean update shared by UDPO and :class:`~sb3_pilot.sac.LeanSAC`: SAC's temperature, critic and target-network steps
with the critics as one ensemble, fused Adam, one ``foreach`` target update, the losses read from the device once per
``train()`` call, and HER batches gathered in one pass (:class:`~sb3_pilot.common.buffers.LeanHerReplayBuffer`). Same
losses and same numbers as SB3's ``SAC.train`` (up to float rounding), fewer kernels and host reads per gradient step.
"""

import math
from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import torch as th
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.policies import BaseModel
from stable_baselines3.common.save_util import load_from_zip_file, recursive_getattr
from stable_baselines3.common.type_aliases import PyTorchObs, ReplayBufferSamples
from stable_baselines3.her.her_replay_buffer import HerReplayBuffer
from torch import nn

from sb3_pilot.common.buffers import LeanHerReplayBuffer
from sb3_pilot.common.critics import EnsembleCritic, stack_sb3_critic_parameters
from sb3_pilot.common.utils import check_number


def check_update_settings(buffer_size: int, batch_size: int, tau: float, gamma: float) -> None:
    """
    Refuse a replay buffer or a minibatch that could hold no transition, and a soft-update coefficient or a discount
    outside [0, 1], before any work, with a ``ValueError`` naming the argument (SB3 accepts ``buffer_size=0``, fails on
    ``batch_size=0`` when it first samples, and trains on ``tau=2`` or ``gamma=1.5`` until the critics diverge).

    :param buffer_size: size of the replay buffer
    :param batch_size: minibatch size of each gradient step
    :param tau: the soft (Polyak) update coefficient of the target critics
    :param gamma: the discount factor
    """
    check_number("buffer_size", buffer_size, minimum=1, integer=True)
    check_number("batch_size", batch_size, minimum=1, integer=True)
    check_number("tau", tau, minimum=0, maximum=1)
    check_number("gamma", gamma, minimum=0, maximum=1)


def soft_update(params: list[th.Tensor], target_params: list[th.Tensor], tau: float) -> None:
    """
    SB3's ``polyak_update`` as one fused ``foreach`` operation: ``target <- target + tau (param - target)``, in place.

    :param params: parameters to move the targets towards
    :param target_params: the target parameters (same order and shapes)
    :param tau: the soft update coefficient (1: copy)
    """
    if params:
        with th.no_grad():
            th._foreach_lerp_(target_params, params, tau)


def set_training_flags(modules: list[nn.Module], mode: bool) -> None:
    """
    What ``nn.Module.train(mode)`` does to each module of a flat list, without its per-call recursion and
    ``__setattr__`` checks: SB3 switches the policy's mode twice per env step when it trains every step.

    :param modules: every module to switch (a policy and its submodules, but not its target networks)
    :param mode: True for training mode
    """
    for module in modules:
        object.__setattr__(module, "training", mode)


class LossRecorder:
    """
    Losses of the gradient steps of one ``train()`` call, kept as tensors and read from the device once, when
    recorded, instead of one host read (``.item()``) per loss and step.
    """

    def __init__(self) -> None:
        self._values: dict[str, list[th.Tensor]] = {}

    def add(self, name: str, value: th.Tensor) -> None:
        """
        :param name: the logger key under ``train/``
        :param value: a scalar (or one-element) tensor
        """
        self._values.setdefault(name, []).append(value.detach().reshape(()))

    def record(self, logger: Logger) -> None:
        """Record the mean of each loss over the steps as ``train/<name>``."""
        if self._values:
            means = th.stack([th.stack(values).mean() for values in self._values.values()]).tolist()
            record_losses(logger, dict(zip(self._values, means, strict=True)))


def record_losses(logger: Logger, means: dict[str, float]) -> None:
    """
    Record losses as ``train/<name>``, refusing non-finite ones: a loss that overflowed (the critics' first, when the
    temperature runs away) leaves NaN parameters a few thousand steps later, and training on from there is wasted.

    :param logger: the algorithm's logger
    :param means: the mean of each loss over the gradient steps since the last record
    :raise FloatingPointError: where a mean is infinite or NaN (the message holds every mean)
    """
    diverged = [name for name, mean in means.items() if not math.isfinite(mean)]
    if diverged:
        values = ", ".join(f"train/{name}={mean:.3g}" for name, mean in means.items())
        raise FloatingPointError(
            f"Training diverged: {', '.join(f'train/{name}' for name in diverged)} over the last gradient steps is not "
            f"finite ({values}). A runaway temperature is a common cause (in the log, train/ent_coef growing by orders "
            "of magnitude while train/entropy stays under the target entropy): try a lower initial temperature "
            "(ent_coef='auto_0.1') or a lower learning rate."
        )
    for name, mean in means.items():
        logger.record(f"train/{name}", mean)


def q_values(critic: BaseModel, observations: PyTorchObs, actions: th.Tensor) -> th.Tensor:
    """
    ``Q_i(s, a)`` of every critic, shape ``(n_critics, batch, 1)``: one ensemble pass for an :class:`EnsembleCritic`,
    the stacked outputs of any other SB3 critic (e.g. a custom ``ContinuousCritic`` subclass).

    :param critic: the critic
    :param observations: observation batch
    :param actions: action batch
    """
    if isinstance(critic, EnsembleCritic):
        return critic.q_values(observations, actions)
    return th.stack(critic(observations, actions))


@runtime_checkable
class StepHooks(Protocol):
    """
    The extension point of the lean gradient step (:class:`LeanSACSteps`): a policy that has these members takes part
    in every gradient step of :class:`~sb3_pilot.sac.LeanSAC`; any other policy leaves the step as SAC's. The pixel
    policy :class:`~sb3_pilot.pixels.PixelGoalSACPolicy` has them: its image encoder runs once per step, and its
    auxiliary goal prediction joins the critic's loss.
    """

    #: set to True by the algorithm that calls the hooks (so that a policy may refuse to train without them)
    step_hooks_attached: bool

    def encode(self, observations: PyTorchObs) -> Any:
        """
        :param observations: the batch's observations ``s``, once per gradient step
        :return: what the policy's actor and critic read in their place in this step (e.g. their features)
        """

    def encode_next(self, next_observations: PyTorchObs) -> Any:
        """
        :param next_observations: the batch's next observations ``s'``, once per gradient step
        :return: what the actor's next action and the target critic read in their place (e.g. themselves)
        """

    def critic_auxiliary_losses(self, observations: Any) -> dict[str, tuple[float, th.Tensor]]:
        """
        :param observations: what :meth:`encode` returned, after the critic's loss pass on it
        :return: losses to add to the critic's, by name (logged as ``train/<name>``), each with its weight
        """


class LeanSACSteps:
    """
    The steps of SAC's update that UDPO shares, as methods of an SB3 off-policy algorithm that has SAC's attributes
    (``critic``, ``critic_target``, ``log_ent_coef``, ``ent_coef_optimizer``, ``target_entropy``, ``tau``, ...) and
    the lists ``_critic_parameters`` and ``_critic_target_parameters``.
    """

    critic: BaseModel
    critic_target: BaseModel
    log_ent_coef: th.Tensor | None
    ent_coef_optimizer: th.optim.Optimizer | None
    ent_coef_tensor: th.Tensor
    target_entropy: float
    tau: float
    gamma: float
    target_update_interval: int
    batch_norm_stats: list[th.Tensor]
    batch_norm_stats_target: list[th.Tensor]
    _critic_parameters: list[th.Tensor]
    _critic_target_parameters: list[th.Tensor]
    replay_buffer_class: type[ReplayBuffer] | None
    device: th.device
    #: the gradient step captured as CUDA graphs (:mod:`sb3_pilot.common.cuda_graph`), where an algorithm opts in
    _cuda_graph_update: Any = None
    #: the policy's part in each gradient step (:class:`StepHooks`), where it has one (:meth:`_attach_step_hooks`)
    _step_hooks: StepHooks | None = None

    def _use_lean_her(self) -> None:
        """Sample HER batches with :class:`~sb3_pilot.common.buffers.LeanHerReplayBuffer` where SB3's is asked for."""
        if self.replay_buffer_class is HerReplayBuffer:
            self.replay_buffer_class = LeanHerReplayBuffer

    def _attach_step_hooks(self) -> None:
        """Take the policy's :class:`StepHooks` into the gradient step, where it has them."""
        self._step_hooks = self.policy if isinstance(self.policy, StepHooks) else None  # type: ignore[attr-defined]
        if self._step_hooks is not None:
            self._step_hooks.step_hooks_attached = True

    def _encode(self, observations: PyTorchObs) -> Any:
        """
        :param observations: the batch's observations
        :return: the policy's encoding of them for this gradient step (:meth:`StepHooks.encode`), or themselves
        """
        return observations if self._step_hooks is None else self._step_hooks.encode(observations)

    def _encode_next(self, next_observations: PyTorchObs) -> Any:
        """
        :param next_observations: the batch's next observations
        :return: the policy's encoding of them for this step's target (:meth:`StepHooks.encode_next`), or themselves
        """
        return next_observations if self._step_hooks is None else self._step_hooks.encode_next(next_observations)

    def _entropy_coef_step(self, log_prob: th.Tensor, losses: LossRecorder) -> th.Tensor:
        """
        SAC's temperature step: loss ``-log(alpha) (log pi(a|s) + target_entropy)`` on the policy's log-probabilities.

        :param log_prob: ``log pi(a | s)`` of the sampled actions, shape ``(batch, 1)``
        :param losses: where the loss, ``alpha`` and the policy's entropy estimate ``-mean log pi(a|s)`` (``entropy``,
            which the temperature drives to ``target_entropy``) are logged
        :return: ``alpha`` of this gradient step (before the temperature's update, as in SAC), detached
        """
        losses.add("entropy", -log_prob.detach().mean())
        if self.ent_coef_optimizer is None or self.log_ent_coef is None:
            ent_coef = self.ent_coef_tensor
        else:
            log_ent_coef = self.log_ent_coef.detach()
            ent_coef = th.exp(log_ent_coef)
            # the loss is linear in log(alpha): its gradient -mean(log pi + target_entropy) is set, not backpropagated
            entropy_gap = (log_prob.detach() + self.target_entropy).mean()
            losses.add("ent_coef_loss", -log_ent_coef * entropy_gap)
            self.log_ent_coef.grad = -entropy_gap.reshape(self.log_ent_coef.shape)
            self.ent_coef_optimizer.step()
        losses.add("ent_coef", ent_coef)
        return ent_coef

    def _critic_step(
        self, observations: PyTorchObs, actions: th.Tensor, target_q_values: th.Tensor, losses: LossRecorder
    ) -> None:
        """
        SAC's critic step: loss ``1/2 sum_i mean_batch (Q_i(s, a) - y)^2`` for the TD target ``y``, one optimizer step
        (plus the policy's auxiliary losses, weighted, where it has them: :meth:`StepHooks.critic_auxiliary_losses`).

        :param observations: observations ``s`` of the batch (or the policy's encoding of them, :meth:`_encode`)
        :param actions: the buffer's actions ``a``
        :param target_q_values: the TD targets ``y``, shape ``(batch, 1)``
        :param losses: where the loss is logged
        """
        current_q_values = q_values(self.critic, observations, actions)
        critic_loss = 0.5 * ((current_q_values - target_q_values) ** 2).mean(dim=(1, 2)).sum()
        losses.add("critic_loss", critic_loss)
        if self._step_hooks is not None:
            for name, (weight, loss) in self._step_hooks.critic_auxiliary_losses(observations).items():
                losses.add(name, loss)
                critic_loss = critic_loss + weight * loss
        self.critic.optimizer.zero_grad()
        critic_loss.backward()
        self.critic.optimizer.step()

    def _target_q_values(
        self,
        replay_data: ReplayBufferSamples,
        next_actions: th.Tensor,
        next_log_prob: th.Tensor,
        ent_coef: th.Tensor,
        next_observations: Any = None,
    ) -> th.Tensor:
        """
        SAC's TD target ``y = r + gamma (1 - d) (min_i Q'_i(s', a') - alpha log pi(a' | s'))``, without gradients.

        :param replay_data: the sampled batch (its ``discounts`` replace ``gamma`` where the buffer sets them)
        :param next_actions: the policy's actions ``a'`` at the next observations ``s'``
        :param next_log_prob: their ``log pi(a' | s')``, shape ``(batch,)`` or ``(batch, 1)``
        :param ent_coef: ``alpha``
        :param next_observations: what the target critic reads for ``s'`` (the policy's encoding of them,
            :meth:`_encode_next`); None: the batch's next observations
        :return: the targets, shape ``(batch, 1)``
        """
        discounts = replay_data.discounts if replay_data.discounts is not None else self.gamma
        if next_observations is None:
            next_observations = replay_data.next_observations
        with th.no_grad():
            next_q_values = q_values(self.critic_target, next_observations, next_actions).amin(dim=0)
            next_q_values = next_q_values - ent_coef * next_log_prob.reshape(-1, 1)
            return replay_data.rewards + (1 - replay_data.dones) * discounts * next_q_values

    def _actor_loss(
        self, observations: PyTorchObs, actions: th.Tensor, log_prob: th.Tensor, ent_coef: th.Tensor, losses: LossRecorder
    ) -> th.Tensor:
        """
        SAC's actor loss ``E[alpha log pi(a | s) - min_i Q_i(s, a)]`` at the policy's reparameterised actions.

        :param observations: observations ``s`` of the batch
        :param actions: the policy's actions ``a`` there (with their graph)
        :param log_prob: their ``log pi(a | s)``, shape ``(batch, 1)``
        :param ent_coef: ``alpha``
        :param losses: where the loss is logged (``actor_loss``)
        :return: the loss, a scalar tensor
        """
        min_qf_pi = q_values(self.critic, observations, actions).amin(dim=0)
        actor_loss = (ent_coef * log_prob - min_qf_pi).mean()
        losses.add("actor_loss", actor_loss)
        return actor_loss

    def set_parameters(
        self, load_path_or_dict: str | dict[str, Any], exact_match: bool = True, device: th.device | str = "auto"
    ) -> None:
        # Models saved with SB3's twin critics (qf0, qf1: SB3's SAC, sb3-pilot <= 0.2) are stacked into the ensemble
        params = load_path_or_dict
        if not isinstance(params, dict):
            _, params, _ = load_from_zip_file(load_path_or_dict, device=device, load_data=False)
        if isinstance(self.critic, EnsembleCritic):
            stack_sb3_critic_parameters(params, self.critic.n_critics)
        super().set_parameters(params, exact_match=exact_match, device=device)  # type: ignore[misc]
        # the optimizers' state was replaced: a captured update (cuda_graphs) captures anew; a model saved from captured
        # steps has capturable optimizers, which have no step on CPU
        if self._cuda_graph_update is not None:
            self._cuda_graph_update.invalidate()
        if self.device.type == "cpu":
            for name in self._get_torch_save_params()[0]:  # type: ignore[attr-defined]
                optimizer = recursive_getattr(self, name)
                if isinstance(optimizer, th.optim.Optimizer):
                    for group in optimizer.param_groups:
                        group["capturable"] = False

    def dump_logs(self) -> None:
        if self._cuda_graph_update is not None:  # its losses, summed on the device since the last dump
            self._cuda_graph_update.losses.record(self.logger)  # type: ignore[attr-defined]
        super().dump_logs()  # type: ignore[misc]

    def _excluded_save_params(self) -> list[str]:
        excluded = ["_critic_parameters", "_critic_target_parameters", "_cuda_graph_update", "_step_hooks"]
        return [*super()._excluded_save_params(), *excluded]  # type: ignore[misc]

    def _gradient_step(self, replay_data: Any, losses: LossRecorder) -> None:
        """One gradient step of the algorithm on a batch, the target update excluded (pure tensor code)."""
        raise NotImplementedError

    def _run_gradient_steps(
        self, gradient_steps: int, batch_size: int, before_step: Callable[[int], None] | None = None
    ) -> None:
        """
        The loop of ``train``: ``gradient_steps`` times a batch, ``_gradient_step`` and the target update, replayed as
        CUDA graphs where the algorithm captured them (``cuda_graphs``, whose losses are recorded at the log dump),
        else eager (the losses recorded at the end).

        :param gradient_steps: number of gradient steps
        :param batch_size: minibatch size
        :param before_step: called with the step's index before each step's batch is drawn, outside any graph
        """
        if self._cuda_graph_update is not None:
            self._cuda_graph_update.run(gradient_steps, batch_size, before_step)
            return
        losses = LossRecorder()
        for gradient_step in range(gradient_steps):
            if before_step is not None:
                before_step(gradient_step)
            replay_data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[attr-defined]
            self._gradient_step(replay_data, losses)
            self._update_target_critics(gradient_step)
        losses.record(self.logger)  # type: ignore[attr-defined]

    def _update_target_critics(self, gradient_step: int) -> None:
        """SAC's target rule: Polyak averaging every ``target_update_interval`` steps, batch-norm statistics copied."""
        if gradient_step % self.target_update_interval == 0:
            soft_update(self._critic_parameters, self._critic_target_parameters, self.tau)
            soft_update(self.batch_norm_stats, self.batch_norm_stats_target, 1.0)
