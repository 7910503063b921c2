"""
Distillation stage of PILoT (paper section 3.2, eq. "distill"): from a goal-reaching teacher (UDPO's state planner, or
any SB3 agent's steps) to a goal planner.
"""

from __future__ import annotations

import os
import sys
import warnings
from typing import NamedTuple

import numpy as np
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.buffers import DictReplayBuffer
from stable_baselines3.common.logger import HumanOutputFormat, Logger
from stable_baselines3.common.type_aliases import GymEnv
from stable_baselines3.common.vec_env import VecEnv, VecNormalize, unwrap_vec_normalize
from stable_baselines3.her.her_replay_buffer import HerReplayBuffer
from tqdm.auto import tqdm

from sb3_pilot.common.distributions import gaussian_expected_nll
from sb3_pilot.common.utils import check_number, task_id
from sb3_pilot.distill.goal_planner import GoalPlanner, env_goal_space
from sb3_pilot.distill.teacher import DETERMINISTIC_TEACHER_NOISE, check_teacher, is_deterministic, load_teacher
from sb3_pilot.udpo import UDPO


def goal_scaling(vec_normalize: VecNormalize | None, goal_dim: int) -> tuple[np.ndarray, np.ndarray]:
    """
    Scale and offset mapping goals as the policy sees them back to raw goals: ``raw = scale * seen + offset``.

    :param vec_normalize: the ``VecNormalize`` wrapper the policy was trained with, if any
    :param goal_dim: size of the goal vectors
    :return: ``(scale, offset)``, the identity when ``achieved_goal`` is not normalised
    """
    if vec_normalize is not None and vec_normalize.norm_obs and "achieved_goal" in (vec_normalize.norm_obs_keys or []):
        stats = vec_normalize.obs_rms["achieved_goal"]  # type: ignore[index]
        return np.sqrt(stats.var + vec_normalize.epsilon).astype(np.float32), stats.mean.astype(np.float32)
    return np.ones(goal_dim, dtype=np.float32), np.zeros(goal_dim, dtype=np.float32)


def teacher_goal_distribution(
    model: UDPO, observations: dict[str, np.ndarray], chunk_size: int = 4096
) -> tuple[np.ndarray, np.ndarray]:
    """
    The teacher's planned next goal from states ``s`` for targets ``g_target``, in raw coordinates: the goal slice
    ``phi(s')`` of the planned next state ``s' ~ h(. | s, g_target)`` (``labels="planned"``).

    :param model: the teacher (a trained ``UDPO`` on a Dict goal env)
    :param observations: raw observations (as the replay buffer stores them), batched
    :param chunk_size: forward pass size
    :return: mean and standard deviation of the teacher's (Gaussian) next goal, shape (n, goal_dim) each
    """
    policy = model.policy
    goal_slice = policy.goal_slice
    assert goal_slice is not None
    vec_normalize = model.get_vec_normalize_env()
    scale, offset = goal_scaling(vec_normalize, goal_slice.stop - goal_slice.start)
    seen = vec_normalize.normalize_obs(observations) if vec_normalize is not None else observations
    policy.set_training_mode(False)
    means, stds = [], []
    n_obs = len(observations["achieved_goal"])
    with th.no_grad():
        for start in range(0, n_obs, chunk_size):
            chunk = {key: value[start : start + chunk_size] for key, value in seen.items()}  # type: ignore[union-attr]
            obs_tensor, _ = policy.obs_to_tensor(chunk)
            distribution = policy.state_planner.distribution(obs_tensor)
            means.append(distribution.mean[:, goal_slice].cpu().numpy())
            stds.append(th.exp(distribution.delta_log_std)[:, goal_slice].cpu().numpy())
    return np.concatenate(means) * scale + offset, np.concatenate(stds) * scale


def _teacher_buffer(model: UDPO) -> DictReplayBuffer:
    buffer = model.replay_buffer
    if not isinstance(buffer, DictReplayBuffer) or (buffer.pos == 0 and not buffer.full):
        raise ValueError(
            "labels='planned' samples states and target goals from the model's replay buffer, which is empty (a loaded "
            "model has none: train it, or call model.load_replay_buffer(path) first)."
        )
    return buffer


class DistillationData(NamedTuple):
    """
    Pairs ``(g, g_target)`` and the teacher's Gaussian over the next goal ``phi(s')``, ``s' ~ h(. | s, g_target)``, in raw
    goal coordinates (tensors of shape (n, goal_dim)).

    :param achieved_goal: ``g = phi(s)``
    :param desired_goal: ``g_target``
    :param teacher_mean: mean of the teacher's next goal
    :param teacher_std: its standard deviation
    """

    achieved_goal: th.Tensor
    desired_goal: th.Tensor
    teacher_mean: th.Tensor
    teacher_std: th.Tensor

    def rows(self, index: slice | th.Tensor) -> DistillationData:
        """The pairs at ``index`` (a slice or an index tensor)."""
        return DistillationData(*(field[index] for field in self))


class HoldoutReport(NamedTuple):
    """
    The student measured against the teacher on held-out pairs.

    :param nll: student's negative log-likelihood of labels sampled from the teacher
    :param landmark_distance: mean distance between the student's and the teacher's mean next goals
    """

    nll: float
    landmark_distance: float


def sample_buffer_pairs(buffer: DictReplayBuffer, n_samples: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """
    Observations of states ``s ~ B`` with target goals ``g_target ~ p_g`` drawn independently from the desired goals
    stored in the buffer (eq. "distill"), raw as the buffer stores them.

    :param buffer: the teacher's replay buffer
    :param n_samples: number of pairs
    :param rng: random generator
    :return: batched observations whose ``desired_goal`` is the drawn target goal
    """
    n_stored = (buffer.buffer_size if buffer.full else buffer.pos) * buffer.n_envs
    # a device-resident buffer (``storage="device"``) holds tensors: read them as host arrays
    stored = {
        key: np.asarray(
            value[: n_stored // buffer.n_envs].cpu() if th.is_tensor(value) else value[: n_stored // buffer.n_envs]
        ).reshape(n_stored, -1)
        for key, value in buffer.observations.items()
    }
    state_idx, goal_idx = rng.integers(n_stored, size=n_samples), rng.integers(n_stored, size=n_samples)
    observations = {key: value[state_idx] for key, value in stored.items()}
    observations["desired_goal"] = stored["desired_goal"][goal_idx]
    return observations


class Rollouts(NamedTuple):
    """
    The teacher's steps (:func:`rollout_pairs`), in raw coordinates.

    :param observations: the observations ``s`` (with their ``desired_goal``, the target ``g_target``), batched
    :param next_goals: the achieved goal ``phi(s_{t+1})`` each step reached (``phi(s_{t+stride})`` with a ``stride``)
    :param success: the success rate of the episodes that ended (NaN: none ended, or the env reports no success)
    :param goal_steps: the number of steps whose ``info`` reports the goal reached (None: the env reports no success)
    """

    observations: dict[str, np.ndarray]
    next_goals: np.ndarray
    success: float
    goal_steps: int | None


def _reported_success(info: dict) -> float:
    """SB3's ``is_success``, else gymnasium-robotics' mazes' ``success``, else NaN (unknown)."""
    return float(info.get("is_success", info.get("success", np.nan)))


def strided_labels(reached: np.ndarray, breaks: np.ndarray, stride: int) -> np.ndarray:
    """
    The goal each step's pair is labelled with: the goal reached ``stride`` steps later, or at the step that ends the
    pair's episode or changes its target goal, if sooner.

    :param reached: the goal each step reached, ``phi(s_{t+1})``, shape (steps, n_envs, goal_dim)
    :param breaks: whether step ``t`` ends its episode or is the last one towards its target goal, shape (steps, n_envs)
    :param stride: steps per label (1: the next goal, ``reached`` itself)
    :return: labels of the first ``steps - stride + 1`` steps (those whose window the rollout holds), same layout
    """
    n_labels = len(reached) - stride + 1
    labels, open_ = reached[:n_labels].copy(), ~breaks[:n_labels]
    for offset in range(1, stride):
        labels[open_] = reached[offset : offset + n_labels][open_]
        open_ &= ~breaks[offset : offset + n_labels]
    return labels


def rollout_pairs(
    model: BaseAlgorithm,
    env: GymEnv,
    n_samples: int,
    seed: int,
    deterministic: bool = False,
    noise: float = 0.0,
    stride: int = 1,
) -> Rollouts:
    """
    Run the teacher's policy ``pi(a | s, g_target)`` in ``env`` for ``n_samples`` steps and record, at every step, the
    pair ``(g, g_target)`` and the goal ``phi(s_{t+1})`` the step actually reached, in raw goal coordinates (with
    ``stride``, the goal reached ``stride`` steps later: :func:`strided_labels`).

    :param model: the teacher, any SB3 agent with continuous actions
    :param env: the env the teacher acts in (observations as the policy sees them: with its ``VecNormalize``, if
        any, whose statistics are left unchanged)
    :param n_samples: number of steps (over all sub-environments)
    :param seed: seed of the env's resets, of the sampled actions and of the noise
    :param deterministic: act with the policy's deterministic action (UDPO: ``I(s, E[h])``); False samples actions
    :param noise: standard deviation of Gaussian noise added to the normalised action (in ``[-1, 1]``, clipped there)
    :param stride: steps between a pair and its label (the rollout runs ``stride - 1`` steps more per env)
    :return: the steps (:class:`Rollouts`)
    """
    venv = env if isinstance(env, VecEnv) else model._wrap_env(env)
    vec_normalize = unwrap_vec_normalize(venv)
    was_training = vec_normalize is not None and vec_normalize.training
    rng = np.random.default_rng(seed)
    seen: list[dict[str, np.ndarray]] = []  # observations as the policy sees them, and the goals reached
    reached_goals: list[np.ndarray] = []
    breaks: list[np.ndarray] = []  # the step ends its episode, or its target goal changes after it
    successes: list[float] = []
    step_successes: list[float] = []
    try:
        if vec_normalize is not None:
            vec_normalize.training = False
        venv.seed(seed)
        obs = venv.reset()
        assert isinstance(obs, dict)
        with th.random.fork_rng(devices=[]):
            th.manual_seed(seed)
            for _ in range(-(-n_samples // venv.num_envs) + stride - 1):
                actions, _ = model.predict(obs, deterministic=deterministic)
                if noise > 0:
                    noisy = model.policy.scale_action(actions) + noise * rng.standard_normal(actions.shape)
                    actions = model.policy.unscale_action(np.clip(noisy, -1.0, 1.0))
                next_obs, _, dones, infos = venv.step(actions)
                assert isinstance(next_obs, dict)
                reached = next_obs["achieved_goal"].copy()
                step_successes.extend(_reported_success(info) for info in infos)
                for index in np.flatnonzero(dones):  # the env reset: the real next state is the terminal observation
                    reached[index] = infos[index]["terminal_observation"]["achieved_goal"]
                    successes.append(_reported_success(infos[index]))
                changed = np.any(
                    next_obs["desired_goal"] != obs["desired_goal"], axis=tuple(range(1, obs["desired_goal"].ndim))
                )
                seen.append(obs)
                reached_goals.append(reached)
                breaks.append(dones | changed)
                obs = next_obs
    finally:
        if vec_normalize is not None:
            vec_normalize.training = was_training
    if venv is model.get_env():  # its episodes were cut: the next learn() starts new ones
        model._last_obs = None  # type: ignore[assignment]
        if isinstance(getattr(model, "replay_buffer", None), HerReplayBuffer):
            model.replay_buffer.truncate_last_trajectory()  # type: ignore[attr-defined]
    observations = {key: np.concatenate([obs[key] for obs in seen])[:n_samples] for key in seen[0]}
    labels = strided_labels(np.stack(reached_goals), np.stack(breaks), stride)
    next_goals = labels.reshape(-1, labels.shape[-1])[:n_samples]
    if vec_normalize is not None:  # back to raw coordinates, once
        next_goals = vec_normalize.unnormalize_obs({**observations, "achieved_goal": next_goals})["achieved_goal"]
        observations = vec_normalize.unnormalize_obs(observations)  # type: ignore[assignment]
    known = [success for success in successes if not np.isnan(success)]
    known_steps = [success for success in step_successes if not np.isnan(success)]
    return Rollouts(
        observations,
        next_goals,
        float(np.mean(known)) if known else np.nan,
        int(np.sum(known_steps)) if known_steps else None,
    )


def distillation_data(
    model: BaseAlgorithm,
    n_samples: int,
    seed: int,
    labels: str = "rollouts",
    env: GymEnv | None = None,
    deterministic: bool = False,
    rollout_noise: float = 0.0,
    allow_unsuccessful_teacher: bool = False,
    stride: int = 1,
) -> tuple[DistillationData, dict[str, float]]:
    """
    ``n_samples`` pairs ``(g, g_target)`` labelled with the teacher's next goal: real steps of its episodes in
    ``env`` (``labels="rollouts"``, :func:`rollout_pairs`, a label of standard deviation 0), or drawn from a UDPO
    teacher's buffer (:func:`sample_buffer_pairs`) and labelled with its planned next goal
    (:func:`teacher_goal_distribution`, ``labels="planned"``).

    :param model: the teacher (checked by :func:`~sb3_pilot.distill.teacher.check_teacher`)
    :param n_samples: number of pairs
    :param seed: seed of the draw (or of the env's resets)
    :param labels: ``"rollouts"`` or ``"planned"``
    :param env: the env of the rollouts (default: the model's)
    :param deterministic: the rollouts' actions (see :func:`rollout_pairs`)
    :param rollout_noise: the rollouts' action noise (see :func:`rollout_pairs`)
    :param allow_unsuccessful_teacher: go on when the rollouts reach no goal (else a ``ValueError``)
    :param stride: the rollouts' steps from a pair to its label (see :func:`rollout_pairs`)
    :return: the pairs, and facts about them for the planner's metadata
    """
    facts: dict[str, float] = {}
    if labels == "rollouts":
        env = model.get_env() if env is None else env
        assert env is not None, "check_teacher refuses a teacher without env"
        rollouts = rollout_pairs(model, env, n_samples, seed, deterministic, rollout_noise, stride)
        if rollouts.goal_steps == 0 and not allow_unsuccessful_teacher:
            raise ValueError(
                f"The {type(model).__name__} teacher's rollouts reached no goal in {n_samples} steps: a planner "
                "distilled from them would plan the steps of an agent that does not reach its goals. Train the "
                "teacher longer, or check the env it acts in (its VecNormalize statistics, env kwargs and wrappers), "
                "or pass allow_unsuccessful_teacher=True to distil it anyway."
            )
        observations, teacher_mean, facts["rollout_success"] = rollouts.observations, rollouts.next_goals, rollouts.success
        facts["rollout_goal_steps"] = np.nan if rollouts.goal_steps is None else rollouts.goal_steps
        teacher_std = np.zeros_like(teacher_mean)
    else:
        assert isinstance(model, UDPO), "check_teacher refuses planned labels of other agents"
        observations = sample_buffer_pairs(_teacher_buffer(model), n_samples, np.random.default_rng(seed))
        teacher_mean, teacher_std = teacher_goal_distribution(model, observations)
    arrays = (observations["achieved_goal"], observations["desired_goal"], teacher_mean, teacher_std)
    data = DistillationData(*(th.as_tensor(array, device=model.device, dtype=th.float32) for array in arrays))
    return data, facts


def distillation_loss(planner: GoalPlanner, batch: DistillationData) -> th.Tensor:
    """
    The student's expected negative log-likelihood of the teacher's next goals (eq. "distill"),
    ``E_{g' ~ N(teacher_mean, teacher_std)} [-log f(g' | g, g_target)]``, in closed form: the optimum of sampling
    labels, without the sampling noise.

    :param planner: the student
    :param batch: the pairs and their teacher distributions
    """
    delta_mean, log_std = planner.distribution_params(batch.achieved_goal, batch.desired_goal)
    return gaussian_expected_nll(batch.teacher_mean - batch.achieved_goal, batch.teacher_std, delta_mean, log_std).mean()


def holdout_report(planner: GoalPlanner, holdout: DistillationData, labels: th.Tensor) -> HoldoutReport:
    """
    :param planner: the student
    :param holdout: held-out pairs
    :param labels: next goals sampled from the teacher at those pairs
    """
    with th.no_grad():
        nll = planner.nll(labels, holdout.achieved_goal, holdout.desired_goal).mean().item()
        student = planner(holdout.achieved_goal, holdout.desired_goal)
        distance = th.linalg.norm(student - holdout.teacher_mean, dim=1).mean().item()
    return HoldoutReport(nll, distance)


def fit_goal_planner(
    planner: GoalPlanner,
    data: DistillationData,
    gradient_steps: int,
    batch_size: int,
    learning_rate: float,
    generator: th.Generator,
    logger: Logger,
    log_interval: int,
    progress_bar: bool = False,
) -> None:
    """
    Minimise :func:`distillation_loss` with Adam on minibatches of ``data``.

    :param planner: the student (trained in place)
    :param data: training pairs
    :param gradient_steps: number of gradient steps
    :param batch_size: minibatch size
    :param learning_rate: Adam learning rate
    :param generator: random generator of the minibatches
    :param logger: where ``distill/loss`` goes every ``log_interval`` steps
    :param log_interval: gradient steps between two logger dumps
    :param progress_bar: show a progress bar
    """
    optimizer = th.optim.Adam(planner.parameters(), lr=learning_rate)
    planner.train()
    n_train, losses = len(data.achieved_goal), []
    for step in tqdm(range(1, gradient_steps + 1), disable=not progress_bar, desc="distilling goal planner"):
        batch = data.rows(th.randint(n_train, (batch_size,), generator=generator, device=data.achieved_goal.device))
        loss = distillation_loss(planner, batch)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.detach())
        if step % log_interval == 0 or step == gradient_steps:
            logger.record("distill/loss", th.stack(losses).mean().item())
            logger.record("distill/gradient_steps", step)
            logger.dump(step)
            losses = []
    planner.eval()


def distill_goal_planner(
    model: BaseAlgorithm | str | os.PathLike,
    n_samples: int = 50_000,
    gradient_steps: int = 5_000,
    batch_size: int = 256,
    learning_rate: float = 1e-3,
    net_arch: list[int] | None = None,
    holdout_fraction: float = 0.1,
    source_task: str | None = None,
    seed: int = 0,
    progress_bar: bool = False,
    logger: Logger | None = None,
    log_interval: int = 1000,
    verbose: int = 0,
    labels: str = "rollouts",
    env: GymEnv | None = None,
    deterministic: bool = False,
    support_size: int = 20_000,
    rollout_noise: float | None = None,
    allow_unsuccessful_teacher: bool = False,
    stride: int = 1,
) -> GoalPlanner:
    """
    Distil a goal-reaching teacher into a goal planner ``f(g' | g, g_target)`` (the student) by maximum likelihood,
    paper eq. "distill". The teacher is any SB3 agent with continuous actions trained on a goal env (SAC, TD3, DDPG,
    sb3-contrib's TQC, :class:`~sb3_pilot.sac.LeanSAC`, :class:`~sb3_pilot.UDPO`, a model of an RL-Zoo run), or the
    path of its file (:func:`~sb3_pilot.distill.teacher.load_teacher`).

    By default (``labels="rollouts"``) the teacher's policy runs ``n_samples`` steps in ``env`` towards the env's own
    goals, and each step gives a pair ``(g, g_target)`` labelled with the goal ``phi(s_{t+1})`` that step really
    reached: **a landmark of the distilled planner is an immediate one, the next goal the teacher reached in one step
    from ``g`` on its way to ``g_target``**. Every label is a real position; for landmarks that must be real positions
    (guidance) the planner keeps ``support_size`` of the pairs' achieved goals, and ``plan(..., snap=True)`` replaces
    each landmark by the nearest of them (:meth:`GoalPlanner.snap`). It costs ``n_samples`` env steps and needs no
    replay buffer. A teacher whose rollouts reach no goal is refused (``allow_unsuccessful_teacher``).

    With ``labels="planned"`` (the paper's eq. "distill", a UDPO teacher only) states ``s ~ B`` are drawn from the
    model's replay buffer and target goals ``g_target ~ p_g`` independently from the desired goals stored in it, and
    the label is ``phi(s')``, the achieved-goal slice of the teacher's planned next state ``s' ~ h(. | s, g_target)``,
    mapped back to raw coordinates with the model's ``VecNormalize`` statistics. The loss (:func:`distillation_loss`)
    is the student's expected NLL of the teacher's Gaussian, in closed form (a real step: standard deviation 0).

    ``planner.metadata`` records the source task and its declared goal space (``goal_space_id``), the teacher's
    algorithm (``teacher_algorithm``), the labels, ``rollout_success`` (the success rate of the rollouts' ended
    episodes), ``rollout_goal_steps`` (how many rollout steps reached their goal: the measure where the goal moves on
    once reached, ``reset_target``, and an episode's last step is rarely at one) and ``holdout``: the student against
    the teacher on a held-out share of the pairs, before and after training (``nll``, ``landmark_distance``, their
    ``*_untrained`` values, and ``teacher_step``, the mean distance from ``g`` to the teacher's next goal, for
    scale). A student no closer to the teacher's next goals than an untrained one,
    which stays put (``landmark_distance`` at least :data:`STAY_PUT_RATIO` of ``landmark_distance_untrained``), is
    warned about: its landmarks are the agent's own position. That is what a teacher whose one step is small against
    its spread gives (a slow agent, or one whose step follows its velocity more than its goal, as PointMaze's ball):
    ``stride=N`` labels each pair with the goal reached ``N`` steps later (``labels="rollouts"``), so that one planner
    step is ``N`` teacher steps.

    :param model: the trained teacher, or the path of its file
    :param n_samples: number of (state, target goal) pairs (env steps for ``"rollouts"``), held-out ones included
    :param gradient_steps: number of gradient steps
    :param batch_size: minibatch size
    :param learning_rate: Adam learning rate
    :param net_arch: hidden layers of the goal planner (default ``[256, 256]``)
    :param holdout_fraction: share of the samples held out for the report
    :param source_task: the task the teacher was trained on (default: read from ``env`` or ``model.get_env()``)
    :param seed: seed of the sampling, the initialisation and the minibatches (same seed, same planner)
    :param progress_bar: show a progress bar
    :param logger: SB3 logger for ``distill/*`` values (default: stdout if ``verbose >= 1``, else none)
    :param log_interval: gradient steps between two logger dumps
    :param verbose: verbosity level: 0 no output, 1 losses and report
    :param labels: ``"rollouts"`` (real next goals of the teacher's steps) or ``"planned"`` (UDPO's plans, see above)
    :param env: the env of the ``"rollouts"`` (default: the model's; its current episodes end, and a model's next
        ``learn()`` starts new ones), with the teacher's ``VecNormalize`` statistics if it was trained with them
    :param deterministic: with ``"rollouts"``, act with the policy's deterministic action; by default actions are
        sampled from the teacher's policy, so the labels are its next-goal *distribution*, realised, and the states
        cover the neighbourhood of its paths that the chained landmarks visit
    :param support_size: number of the training pairs' achieved goals (drawn at random) kept as the planner's
        support for ``snap=True`` (0: none)
    :param rollout_noise: with ``"rollouts"``, standard deviation of Gaussian noise on the normalised action (in
        ``[-1, 1]``); None: 0.1 for a teacher whose policy is deterministic (TD3, DDPG: its rollouts would otherwise
        have no spread) unless ``deterministic``, 0 for the others
    :param allow_unsuccessful_teacher: distil a teacher whose rollouts reach no goal (refused by default)
    :param stride: with ``"rollouts"``, teacher steps from a pair ``(g, g_target)`` to its label: the goal reached
        ``stride`` steps later, or where the episode ends or ``g_target`` changes, if sooner (1: the next goal)
    :return: the distilled goal planner (on the model's device)
    """
    check_number("holdout_fraction", holdout_fraction, minimum=0, strict=True)
    check_number("learning_rate", learning_rate, minimum=0, strict=True)
    for name, value in (("n_samples", n_samples), ("gradient_steps", gradient_steps), ("batch_size", batch_size)):
        check_number(name, value, minimum=1, integer=True)
    check_number("support_size", support_size, minimum=0, integer=True)
    check_number("stride", stride, minimum=1, integer=True)
    if stride > 1 and labels != "rollouts":
        raise ValueError(f"stride={stride} labels the teacher's real steps: it needs labels='rollouts', not {labels!r}.")
    if rollout_noise is not None:
        check_number("rollout_noise", rollout_noise, minimum=0)
    if holdout_fraction >= 1:
        raise ValueError(f"holdout_fraction must be in (0, 1), got {holdout_fraction}.")
    n_holdout = round(holdout_fraction * n_samples)
    if n_holdout < 1 or n_samples - n_holdout < batch_size:
        raise ValueError(
            f"n_samples={n_samples} leaves {n_holdout} held-out and {n_samples - n_holdout} training samples: "
            f"need >= 1 and >= batch_size={batch_size}."
        )
    if isinstance(model, (str, os.PathLike)):
        model = load_teacher(model, env=env)
    check_teacher(model, labels, env)
    source_env = env if env is not None else model.get_env()
    if source_task is None:
        if source_env is None:
            raise ValueError("The model has no env to read the source task from: pass source_task=<its Gymnasium ID>.")
        source_task = task_id(source_env)
    if rollout_noise is None:
        rollout_noise = DETERMINISTIC_TEACHER_NOISE if is_deterministic(model) and not deterministic else 0.0
    goal_space = env_goal_space(source_env) if source_env is not None else None
    if logger is None:
        logger = Logger(None, [HumanOutputFormat(sys.stdout)] if verbose >= 1 else [])

    data, facts = distillation_data(
        model, n_samples, seed, labels, env, deterministic, rollout_noise, allow_unsuccessful_teacher, stride
    )
    holdout, train = data.rows(slice(n_holdout)), data.rows(slice(n_holdout, None))
    generator = th.Generator(device=model.device).manual_seed(seed)
    holdout_labels = holdout.teacher_mean + holdout.teacher_std * th.randn(
        holdout.teacher_mean.shape, generator=generator, device=model.device
    )
    with th.random.fork_rng(devices=[]):
        th.manual_seed(seed)
        metadata = {
            "source_task": source_task,
            **({"goal_space_id": goal_space} if goal_space is not None else {}),
            "teacher_algorithm": type(model).__name__,
            "n_samples": len(train.achieved_goal),
            "gradient_steps": gradient_steps,
            "seed": seed,
            "teacher_num_timesteps": model.num_timesteps,
            "labels": labels,
            **({"deterministic": deterministic, "rollout_noise": rollout_noise} if labels == "rollouts" else {}),
            **({"stride": stride} if stride > 1 else {}),
            **facts,
        }
        planner = GoalPlanner(data.achieved_goal.shape[1], net_arch, metadata=metadata).to(model.device)
    planner.set_scales(th.cat([train.achieved_goal, train.desired_goal]), train.teacher_mean - train.achieved_goal)

    untrained = holdout_report(planner, holdout, holdout_labels)
    fit_goal_planner(planner, train, gradient_steps, batch_size, learning_rate, generator, logger, log_interval, progress_bar)
    trained = holdout_report(planner, holdout, holdout_labels)
    # drawn after the fit: the same seed gives the same weights with any support_size
    support = th.randperm(len(train.achieved_goal), generator=generator, device=model.device)[:support_size]
    planner.set_support(train.achieved_goal[support])
    planner.metadata["support_size"] = len(support)

    report = {
        **{f"{key}_untrained": value for key, value in untrained._asdict().items()},
        "teacher_step": th.linalg.norm(holdout.teacher_mean - holdout.achieved_goal, dim=1).mean().item(),
        **trained._asdict(),
    }
    planner.metadata["holdout"] = report
    for key, value in report.items():
        logger.record(f"distill/holdout_{key}", value)
    logger.dump(gradient_steps)
    if stays_put(report):
        warnings.warn(stay_put_message(report, stride), stacklevel=2)
    return planner


#: A student whose held-out landmarks are at least this share of an untrained one's distance from the teacher's next
#: goals learnt nothing beyond staying put (:func:`stays_put`).
STAY_PUT_RATIO = 0.9


def stays_put(holdout: dict[str, float]) -> bool:
    """
    :param holdout: a planner's ``metadata["holdout"]``
    :return: whether the student learnt nothing beyond staying put (:data:`STAY_PUT_RATIO`)
    """
    return holdout["landmark_distance"] >= STAY_PUT_RATIO * holdout["landmark_distance_untrained"]


def stay_put_message(holdout: dict[str, float], stride: int) -> str:
    """What a planner that stays put is, and what to do (:func:`distill_goal_planner`'s warning)."""
    return (
        f"The distilled planner learnt nothing beyond staying put: its held-out landmarks are "
        f"{holdout['landmark_distance']:.4g} from the teacher's next goals, an untrained planner's (the agent's own "
        f"goal) {holdout['landmark_distance_untrained']:.4g}, a teacher step being {holdout['teacher_step']:.4g} "
        f"(stride {stride}). The teacher's step is too small or too noisy to plan from where it is. If its goal stays "
        "once reached (PointMaze's continuing task), most steps hover there and few start and goal pairs are seen: "
        "distil on rollouts whose goal moves on (env=gym.make(..., reset_target=True); zoo distill --env-kwargs "
        "reset_target:True). Else distil with a larger stride (e.g. stride=10: landmarks 10 teacher steps ahead), or "
        "train the teacher on."
    )
