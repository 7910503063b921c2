"""Distillation stage of PILoT (paper section 3.2, eq. "distill"): from UDPO's state planner to a goal planner."""

from __future__ import annotations

import sys
import warnings
from typing import NamedTuple

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import DictReplayBuffer
from stable_baselines3.common.logger import HumanOutputFormat, Logger
from stable_baselines3.common.type_aliases import GymEnv
from stable_baselines3.common.vec_env import VecEnv, VecNormalize, unwrap_vec_normalize
from stable_baselines3.her.her_replay_buffer import HerReplayBuffer
from tqdm.auto import tqdm

from sb3_pilot.common.distributions import gaussian_expected_nll
from sb3_pilot.common.utils import check_number, task_id
from sb3_pilot.distill.goal_planner import GoalPlanner
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


#: What the distillation labels are: real next goals of the teacher's episodes (:func:`rollout_pairs`), or the
#: teacher's model of them (:func:`teacher_goal_distribution`)
LABELS = ("rollouts", "reached", "planned")


def teacher_goal_distribution(
    model: UDPO, observations: dict[str, np.ndarray], chunk_size: int = 4096, labels: str = "planned"
) -> tuple[np.ndarray, np.ndarray]:
    """
    The teacher's next goal from states ``s`` for targets ``g_target``, in raw coordinates:

    * ``labels="planned"``: the goal slice ``phi(s')`` of the planned next state ``s' ~ h(. | s, g_target)``;
    * ``labels="reached"``: the goal slice of the next state the teacher's deterministic action
      ``a = I(s, E[h(. | s, g_target)])`` reaches, as its forward dynamics model ``T(s' | s, a)`` predicts it
      (needs ``plan_target="policy"``): what the teacher's plan actually leads to, an immediate landmark.

    :param model: the teacher (a trained ``UDPO`` on a Dict goal env)
    :param observations: raw observations (as the replay buffer stores them), batched
    :param chunk_size: forward pass size
    :param labels: ``"reached"`` or ``"planned"``
    :return: mean and standard deviation of the teacher's (Gaussian) next goal, shape (n, goal_dim) each
    """
    if labels not in ("reached", "planned"):
        raise ValueError(f'labels must be "reached" or "planned" here, got {labels!r}.')
    forward_dynamics = model.policy.forward_dynamics
    if labels == "reached" and forward_dynamics is None:
        raise ValueError('labels="reached" needs a teacher trained with plan_target="policy" (its forward dynamics).')
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
            mean, log_std = distribution.mean, distribution.delta_log_std
            if labels == "reached":
                assert forward_dynamics is not None
                actions, _ = policy.inverse_dynamics(distribution.state, mean, deterministic=True)
                delta_mean, log_std = forward_dynamics.distribution_params(distribution.state, actions)
                mean = distribution.state + delta_mean
            means.append(mean[:, goal_slice].cpu().numpy())
            stds.append(th.exp(log_std)[:, goal_slice].cpu().numpy())
    return np.concatenate(means) * scale + offset, np.concatenate(stds) * scale


def _check_teacher(model: UDPO) -> None:
    if not isinstance(model.observation_space, spaces.Dict) or model.policy.goal_slice is None:
        raise ValueError(
            "distill_goal_planner needs a UDPO trained on a goal env (Dict observation with 'achieved_goal' and "
            f"'desired_goal'), got observation space {model.observation_space}."
        )
    if "desired_goal" not in model.observation_space.spaces:
        raise ValueError("distill_goal_planner needs 'desired_goal' in the observation: it is the target goal g_target.")
    if model.num_timesteps == 0:
        raise ValueError(
            "distill_goal_planner needs a trained teacher, but the model has taken 0 env steps (num_timesteps=0): "
            "call model.learn(...) first, or load a trained model."
        )
    if model._n_updates == 0:
        warnings.warn(
            f"The teacher has taken {model.num_timesteps} env steps but no gradient step (learning_starts="
            f"{model.learning_starts}): its state planner and inverse dynamics are still their random initialisation, "
            "and so will the distilled planner's landmarks be.",
            stacklevel=3,
        )


def _teacher_buffer(model: UDPO) -> DictReplayBuffer:
    buffer = model.replay_buffer
    if not isinstance(buffer, DictReplayBuffer) or (buffer.pos == 0 and not buffer.full):
        raise ValueError(
            "labels 'planned' and 'reached' sample states and target goals from the model's replay buffer, which is "
            "empty (a loaded model has none: train it, or call model.load_replay_buffer(path) first)."
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
    stored = {key: value[: n_stored // buffer.n_envs].reshape(n_stored, -1) for key, value in buffer.observations.items()}
    state_idx, goal_idx = rng.integers(n_stored, size=n_samples), rng.integers(n_stored, size=n_samples)
    observations = {key: value[state_idx] for key, value in stored.items()}
    observations["desired_goal"] = stored["desired_goal"][goal_idx]
    return observations


def rollout_pairs(
    model: UDPO, env: GymEnv, n_samples: int, seed: int, deterministic: bool = False
) -> tuple[dict[str, np.ndarray], np.ndarray, float]:
    """
    Run the teacher's policy ``pi(a | s, g_target) = I(a | s, h(s' | s, g_target))`` in ``env`` for ``n_samples`` steps
    and record, at every step, the pair ``(g, g_target)`` and the goal ``phi(s_{t+1})`` the step actually reached:
    what the teacher's plan led to, in raw goal coordinates.

    :param model: the teacher
    :param env: the env the teacher acts in (observations as the policy sees them: with its ``VecNormalize``, if
        any, whose statistics are left unchanged)
    :param n_samples: number of steps (over all sub-environments)
    :param seed: seed of the env's resets and of the sampled actions
    :param deterministic: act with the mean plan's action ``I(s, E[h])``; False samples actions from ``pi``
    :return: raw observations ``s`` (with their ``desired_goal``), the raw achieved goals one step later, and the
        success rate of the episodes that ended
    """
    venv = env if isinstance(env, VecEnv) else model._wrap_env(env)
    vec_normalize = unwrap_vec_normalize(venv)
    was_training = vec_normalize is not None and vec_normalize.training
    seen: list[dict[str, np.ndarray]] = []  # observations as the policy sees them, and the goals reached
    reached_goals: list[np.ndarray] = []
    successes: list[float] = []
    try:
        if vec_normalize is not None:
            vec_normalize.training = False
        venv.seed(seed)
        obs = venv.reset()
        assert isinstance(obs, dict)
        with th.random.fork_rng(devices=[]):
            th.manual_seed(seed)
            for _ in range(-(-n_samples // venv.num_envs)):
                actions, _ = model.predict(obs, deterministic=deterministic)
                next_obs, _, dones, infos = venv.step(actions)
                assert isinstance(next_obs, dict)
                reached = next_obs["achieved_goal"].copy()
                for index in np.flatnonzero(dones):  # the env reset: the real next state is the terminal observation
                    reached[index] = infos[index]["terminal_observation"]["achieved_goal"]
                    # SB3's key, else gymnasium-robotics' mazes' ("success"), else unknown
                    successes.append(float(infos[index].get("is_success", infos[index].get("success", np.nan))))
                seen.append(obs)
                reached_goals.append(reached)
                obs = next_obs
    finally:
        if vec_normalize is not None:
            vec_normalize.training = was_training
    if venv is model.get_env():  # its episodes were cut: the next learn() starts new ones
        model._last_obs = None  # type: ignore[assignment]
        if isinstance(model.replay_buffer, HerReplayBuffer):
            model.replay_buffer.truncate_last_trajectory()
    observations = {key: np.concatenate([obs[key] for obs in seen])[:n_samples] for key in seen[0]}
    next_goals = np.concatenate(reached_goals)[:n_samples]
    if vec_normalize is not None:  # back to raw coordinates, once
        next_goals = vec_normalize.unnormalize_obs({**observations, "achieved_goal": next_goals})["achieved_goal"]
        observations = vec_normalize.unnormalize_obs(observations)  # type: ignore[assignment]
    known = [success for success in successes if not np.isnan(success)]
    return observations, next_goals, float(np.mean(known)) if known else np.nan


def distillation_data(
    model: UDPO,
    n_samples: int,
    seed: int,
    labels: str = "rollouts",
    env: GymEnv | None = None,
    deterministic: bool = False,
) -> tuple[DistillationData, dict[str, float]]:
    """
    ``n_samples`` pairs ``(g, g_target)`` labelled with the teacher's next goal: real steps of its episodes in
    ``env`` (``labels="rollouts"``, :func:`rollout_pairs`, a label of standard deviation 0), or drawn from its buffer
    (:func:`sample_buffer_pairs`) and labelled with its next-goal distribution (:func:`teacher_goal_distribution`).

    :param model: the teacher
    :param n_samples: number of pairs
    :param seed: seed of the draw (or of the env's resets)
    :param labels: ``"rollouts"``, ``"reached"`` or ``"planned"``
    :param env: the env of the rollouts (default: the model's)
    :param deterministic: the rollouts' actions (see :func:`rollout_pairs`)
    :return: the pairs, and facts about them for the planner's metadata
    """
    if labels not in LABELS:
        raise ValueError(f"labels must be one of {LABELS}, got {labels!r}.")
    facts: dict[str, float] = {}
    if labels == "rollouts":
        env = model.get_env() if env is None else env
        if env is None:
            raise ValueError('labels="rollouts" runs the teacher in an env: pass env=, or load the model with one.')
        observations, teacher_mean, facts["rollout_success"] = rollout_pairs(model, env, n_samples, seed, deterministic)
        teacher_std = np.zeros_like(teacher_mean)
    else:
        observations = sample_buffer_pairs(_teacher_buffer(model), n_samples, np.random.default_rng(seed))
        teacher_mean, teacher_std = teacher_goal_distribution(model, observations, labels=labels)
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
    model: UDPO,
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
) -> GoalPlanner:
    """
    Distil a trained UDPO's state planner ``h(s' | s, g_target)`` (the teacher) into a goal planner
    ``f(g' | g, g_target)`` (the student) by maximum likelihood, paper eq. "distill".

    Data (:func:`distillation_data`), by default (``labels="rollouts"``): the teacher's policy
    ``pi(a | s, g_target) = I(a | s, h(s' | s, g_target))`` runs ``n_samples`` steps in ``env`` towards the env's own
    goals, and each step gives a pair ``(g, g_target)`` labelled with the goal ``phi(s_{t+1})`` that step really
    reached. The student therefore learns where the teacher's plan *leads* in one step, not the plan itself: **a
    landmark of the distilled planner is an immediate one, the next goal the source agent reached in one step from
    ``g`` on its way to ``g_target``**, of a real step's length whatever the balance of the teacher's actor loss and
    likelihood term (UDPO's own plan ``E[h]`` over-reaches with a weak ``planner_coef`` and stalls with a strong one).
    Every label is a real position; the student's mean may still land slightly on the wrong side of a wall the teacher
    slides along (``zoo_runs/landmarks/``): for landmarks that must be real positions (guidance), the planner keeps
    ``support_size`` of the achieved goals of the pairs' states, positions the source really occupied, and
    ``plan(..., snap=True)`` replaces each landmark by the nearest of them (:meth:`GoalPlanner.snap`).
    It costs ``n_samples`` env steps and needs no replay buffer. Goals are the env's
    desired goals rather than the paper's ``g_target ~ p_g`` drawn independently of ``s``: the teacher's episodes are
    the only ones whose next goals are real.

    With ``labels="planned"`` (the paper's eq. "distill") states ``s ~ B`` are drawn from the model's replay buffer
    and target goals ``g_target ~ p_g`` independently from the desired goals stored in it, and the label is
    ``phi(s')``, the achieved-goal slice of the teacher's planned next state, mapped back to raw coordinates with the
    model's ``VecNormalize`` statistics (the buffer stores raw observations, the teacher sees normalised ones). With
    ``labels="reached"`` (a teacher trained with ``plan_target="policy"``) the label is where the teacher's
    deterministic action for its plan leads, as its forward dynamics model predicts it (see
    :func:`teacher_goal_distribution`). The loss (:func:`distillation_loss`) is the student's expected NLL of the
    teacher's Gaussian, in closed form (a real step is a Gaussian of standard deviation 0).

    A held-out share of the pairs measures the student against the teacher before and after training, stored in
    ``planner.metadata["holdout"]``: ``nll`` and ``landmark_distance`` (see :class:`HoldoutReport`), with
    ``*_untrained`` values for the initial student, and ``teacher_step`` (mean distance from ``g`` to the teacher's
    mean, for scale).

    :param model: the trained UDPO teacher (on a Dict goal env; with its replay buffer for ``"planned"`` and
        ``"reached"`` labels)
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
    :param labels: ``"rollouts"`` (real next goals of the teacher's episodes), ``"planned"`` or ``"reached"`` (see
        above)
    :param env: the env of the ``"rollouts"`` (default: the model's; its current episodes end, and a model's next
        ``learn()`` starts new ones): pass an evaluation env to leave the training env's episodes and monitor alone
    :param deterministic: with ``"rollouts"``, act with the mean plan's action; by default actions are sampled from
        the teacher's policy, so the labels are its next-goal *distribution*, realised (as eq. "distill" matches the
        distribution of ``h``), and the states cover the neighbourhood of its paths that the chained landmarks visit
    :param support_size: number of the training pairs' achieved goals (drawn at random) kept as the planner's
        support for ``snap=True`` (0: none)
    :return: the distilled goal planner (on the model's device)
    """
    _check_teacher(model)
    check_number("holdout_fraction", holdout_fraction, minimum=0, strict=True)
    check_number("learning_rate", learning_rate, minimum=0, strict=True)
    for name, value in (("n_samples", n_samples), ("gradient_steps", gradient_steps), ("batch_size", batch_size)):
        check_number(name, value, minimum=1, integer=True)
    check_number("support_size", support_size, minimum=0, integer=True)
    if holdout_fraction >= 1:
        raise ValueError(f"holdout_fraction must be in (0, 1), got {holdout_fraction}.")
    n_holdout = round(holdout_fraction * n_samples)
    if n_holdout < 1 or n_samples - n_holdout < batch_size:
        raise ValueError(
            f"n_samples={n_samples} leaves {n_holdout} held-out and {n_samples - n_holdout} training samples: "
            f"need >= 1 and >= batch_size={batch_size}."
        )
    if source_task is None:
        source_env = env if env is not None else model.get_env()
        if source_env is None:
            raise ValueError("The model has no env to read the source task from: pass source_task=<its Gymnasium ID>.")
        source_task = task_id(source_env)
    if logger is None:
        logger = Logger(None, [HumanOutputFormat(sys.stdout)] if verbose >= 1 else [])

    data, facts = distillation_data(model, n_samples, seed, labels, env, deterministic)
    holdout, train = data.rows(slice(n_holdout)), data.rows(slice(n_holdout, None))
    generator = th.Generator(device=model.device).manual_seed(seed)
    holdout_labels = holdout.teacher_mean + holdout.teacher_std * th.randn(
        holdout.teacher_mean.shape, generator=generator, device=model.device
    )
    with th.random.fork_rng(devices=[]):
        th.manual_seed(seed)
        metadata = {
            "source_task": source_task,
            "n_samples": len(train.achieved_goal),
            "gradient_steps": gradient_steps,
            "seed": seed,
            "teacher_num_timesteps": model.num_timesteps,
            "labels": labels,
            **({"deterministic": deterministic} if labels == "rollouts" else {}),
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
    return planner
