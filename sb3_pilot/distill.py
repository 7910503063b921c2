"""Distillation stage of PILoT (paper section 3.2, eq. "distill"): from UDPO's state planner to a goal planner."""

from __future__ import annotations

import sys

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import DictReplayBuffer
from stable_baselines3.common.logger import HumanOutputFormat, Logger
from stable_baselines3.common.vec_env import VecNormalize
from tqdm.auto import tqdm

from sb3_pilot.planner import GoalPlanner, diagonal_gaussian_nll, task_id
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
    The goal slice ``phi(s')`` of the teacher's planned next state ``s' ~ h(. | s, g_target)``, in raw coordinates.

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
            state, delta_mean, log_std = policy.state_planner.distribution_params(obs_tensor)
            means.append((state + delta_mean)[:, goal_slice].cpu().numpy())
            stds.append(th.exp(log_std)[:, goal_slice].cpu().numpy())
    return np.concatenate(means) * scale + offset, np.concatenate(stds) * scale


def _check_teacher(model: UDPO) -> DictReplayBuffer:
    if not isinstance(model.observation_space, spaces.Dict) or model.policy.goal_slice is None:
        raise ValueError(
            "distill_goal_planner needs a UDPO trained on a goal env (Dict observation with 'achieved_goal' and "
            f"'desired_goal'), got observation space {model.observation_space}."
        )
    if "desired_goal" not in model.observation_space.spaces:
        raise ValueError("distill_goal_planner needs 'desired_goal' in the observation: it is the target goal g_target.")
    buffer = model.replay_buffer
    if not isinstance(buffer, DictReplayBuffer) or (buffer.pos == 0 and not buffer.full):
        raise ValueError(
            "distill_goal_planner samples states and target goals from the model's replay buffer, which is empty "
            "(a loaded model has none: train it, or call model.load_replay_buffer(path) first)."
        )
    return buffer


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
) -> GoalPlanner:
    """
    Distil a trained UDPO's state planner ``h(s' | s, g_target)`` (the teacher) into a goal planner
    ``f(g' | g, g_target)`` (the student) by maximum likelihood, paper eq. "distill".

    Data: states ``s ~ B`` are drawn from the model's replay buffer and target goals ``g_target ~ p_g`` independently
    from the desired goals stored in it, as the equation writes. The buffer is the only data the teacher is accurate
    on (it was trained on it), it costs no env step, and it works for a model loaded with its buffer. The label is
    ``phi(s')``, the achieved-goal slice of the teacher's planned next state, mapped back to raw coordinates with the
    model's ``VecNormalize`` statistics (the buffer stores raw observations, the teacher sees normalised ones).
    As the teacher's next goal is a diagonal Gaussian, the loss is the student's expected negative log-likelihood of
    the teacher's samples, computed in closed form: the same optimum as sampling labels, without the sampling noise.

    A held-out share of the samples measures the student against the teacher before and after training; the result
    is stored in ``planner.metadata["holdout"]``: ``nll`` (student's NLL of teacher-sampled labels),
    ``landmark_distance`` (mean distance between student and teacher means) and ``teacher_step`` (mean distance from
    ``g`` to the teacher's mean, for scale), with ``*_untrained`` values for the initial student.

    :param model: the trained UDPO teacher (on a Dict goal env, with its replay buffer)
    :param n_samples: number of (state, target goal) pairs drawn from the buffer, held-out ones included
    :param gradient_steps: number of gradient steps
    :param batch_size: minibatch size
    :param learning_rate: Adam learning rate
    :param net_arch: hidden layers of the goal planner (default ``[256, 256]``)
    :param holdout_fraction: share of the samples held out for the report
    :param source_task: the task the teacher was trained on (default: read from ``model.get_env()``)
    :param seed: seed of the sampling, the initialisation and the minibatches (same seed, same planner)
    :param progress_bar: show a progress bar
    :param logger: SB3 logger for ``distill/*`` values (default: stdout if ``verbose >= 1``, else none)
    :param log_interval: gradient steps between two logger dumps
    :param verbose: verbosity level: 0 no output, 1 losses and report
    :return: the distilled goal planner (on the model's device)
    """
    buffer = _check_teacher(model)
    if not 0 < holdout_fraction < 1:
        raise ValueError(f"holdout_fraction must be in (0, 1), got {holdout_fraction}.")
    n_holdout = round(holdout_fraction * n_samples)
    if n_holdout < 1 or n_samples - n_holdout < batch_size:
        raise ValueError(
            f"n_samples={n_samples} leaves {n_holdout} held-out and {n_samples - n_holdout} training samples: "
            f"need >= 1 and >= batch_size={batch_size}."
        )
    if source_task is None:
        if model.get_env() is None:
            raise ValueError("The model has no env to read the source task from: pass source_task=<its Gymnasium ID>.")
        source_task = task_id(model.get_env())
    if logger is None:
        logger = Logger(None, [HumanOutputFormat(sys.stdout)] if verbose >= 1 else [])

    # s ~ B and g_target ~ p_g, drawn independently from the raw (un-normalised) buffer storage
    n_stored = (buffer.buffer_size if buffer.full else buffer.pos) * buffer.n_envs
    stored = {key: value[: n_stored // buffer.n_envs].reshape(n_stored, -1) for key, value in buffer.observations.items()}
    rng = np.random.default_rng(seed)
    state_idx, goal_idx = rng.integers(n_stored, size=n_samples), rng.integers(n_stored, size=n_samples)
    observations = {key: value[state_idx] for key, value in stored.items()}
    observations["desired_goal"] = stored["desired_goal"][goal_idx]
    teacher_mean, teacher_std = teacher_goal_distribution(model, observations)

    device = model.device
    tensors = [
        th.as_tensor(array, device=device, dtype=th.float32)
        for array in (observations["achieved_goal"], observations["desired_goal"], teacher_mean, teacher_std)
    ]
    train = [tensor[n_holdout:] for tensor in tensors]
    holdout = [tensor[:n_holdout] for tensor in tensors]
    generator = th.Generator(device=device).manual_seed(seed)
    goal_dim = teacher_mean.shape[1]
    holdout_labels = holdout[2] + holdout[3] * th.randn(holdout[2].shape, generator=generator, device=device)

    with th.random.fork_rng(devices=[]):
        th.manual_seed(seed)
        planner = GoalPlanner(
            goal_dim,
            net_arch,
            metadata={
                "source_task": source_task,
                "n_samples": n_samples - n_holdout,
                "gradient_steps": gradient_steps,
                "seed": seed,
                "teacher_num_timesteps": model.num_timesteps,
            },
        ).to(device)
    planner.set_scales(th.cat([train[0], train[1]]), train[2] - train[0])
    optimizer = th.optim.Adam(planner.parameters(), lr=learning_rate)

    def holdout_report(suffix: str = "") -> dict[str, float]:
        achieved, desired, mean, _ = holdout
        with th.no_grad():
            report = {
                f"nll{suffix}": planner.nll(holdout_labels, achieved, desired).mean().item(),
                f"landmark_distance{suffix}": th.linalg.norm(planner(achieved, desired) - mean, dim=1).mean().item(),
            }
        return report

    report = {**holdout_report("_untrained"), "teacher_step": th.linalg.norm(holdout[2] - holdout[0], dim=1).mean().item()}
    planner.train()
    n_train = len(train[0])
    losses = []
    for step in tqdm(range(1, gradient_steps + 1), disable=not progress_bar, desc="distilling goal planner"):
        batch = th.randint(n_train, (batch_size,), generator=generator, device=device)
        achieved, desired, mean, std = (tensor[batch] for tensor in train)
        delta_mean, log_std = planner.distribution_params(achieved, desired)
        # E_{g' ~ N(mean, std)} [-log f(g' | g, g_target)], in closed form
        loss = (
            diagonal_gaussian_nll(mean - achieved, delta_mean, log_std) + 0.5 * ((std * th.exp(-log_std)) ** 2).sum(dim=1)
        ).mean()
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
    report.update(holdout_report())
    planner.metadata["holdout"] = report
    for key, value in report.items():
        logger.record(f"distill/holdout_{key}", value)
    logger.dump(gradient_steps)
    return planner
