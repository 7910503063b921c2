"""
HER sampling of the lean update: SB3's ``HerReplayBuffer`` with real and relabelled transitions gathered at once, its
storage in host memory (numpy, SB3's) or on the model's device (torch tensors, sampled and relabelled there).
"""

import copy
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.type_aliases import DictReplayBufferSamples
from stable_baselines3.common.utils import get_device
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecNormalize
from stable_baselines3.her.goal_selection_strategy import GoalSelectionStrategy
from stable_baselines3.her.her_replay_buffer import HerReplayBuffer

from sb3_pilot.envs.core import torch_reward_twin

#: Where :class:`LeanHerReplayBuffer` stores its transitions
STORAGES = ("host", "device")
#: A device-resident buffer may take at most this fraction of a CUDA device's memory
MAX_DEVICE_MEMORY_FRACTION = 0.5
#: The arrays of SB3's replay buffer that device storage holds as tensors (besides the observation dicts)
_STORED_ARRAYS = ("actions", "rewards", "dones", "timeouts")


def normalize_in_place(obs: dict[str, np.ndarray], env: VecNormalize | None) -> None:
    """
    ``VecNormalize.normalize_obs`` on a dict of arrays that the caller owns, without its deep copy of the dict.

    :param obs: the observations, normalised in place (their normalised keys become float32)
    :param env: the VecNormalize (None: nothing to do)
    """
    if env is None or not env.norm_obs:
        return
    assert isinstance(env.obs_rms, dict) and env.norm_obs_keys is not None
    for key in env.norm_obs_keys:
        obs[key] = env._normalize_obs(obs[key], env.obs_rms[key]).astype(np.float32)


def device_reward_function(env: VecEnv | None, goal_dim: int) -> Callable[[th.Tensor, th.Tensor], th.Tensor] | None:
    """
    The torch twin of the rewards ``env.env_method("compute_reward", ..., indices=[0])`` computes (see
    :func:`~sb3_pilot.envs.core.torch_reward_twin`), for a ``DummyVecEnv`` (possibly wrapped in VecEnv wrappers such
    as ``VecNormalize``); None for any other VecEnv (its envs live in other processes) or an env without a twin.

    :param env: the VecEnv of the buffer
    :param goal_dim: size of the goal vectors
    """
    if env is None or not isinstance(env.unwrapped, DummyVecEnv):
        return None
    return torch_reward_twin(env.unwrapped.envs[0], goal_dim)


class LeanHerReplayBuffer(HerReplayBuffer):
    """
    SB3's ``HerReplayBuffer`` (same arguments, same storage, same samples for the same random state) whose ``sample``
    gathers the real and the relabelled transitions of a batch in one pass: one index gather, one in-place
    normalisation (no deep copy) and one tensor copy per observation key, where SB3's makes two of each and concatenates
    them. The batch holds the real transitions first, then the relabelled ones, as SB3's does.

    With ``storage="device"`` (e.g. ``replay_buffer_kwargs=dict(storage="device")``) the observations (images as
    uint8), goals, actions, rewards, dones, timeouts and the episode bookkeeping are torch tensors on the buffer's
    device (the model's), and a batch is drawn there: valid transitions uniformly (an inclusive prefix sum over the
    buffer, then a binary search: a few kernels, no host read), goals of the "future", "final" or "episode" strategy
    from the same episode, ``VecNormalize``'s normalisation at sampling time in float64 (as numpy computes it) and the
    rewards of relabelled goals:

    - by the env's torch twin of ``compute_reward`` where it has one (the package's tasks: their float64 distance,
      equal rewards; see :func:`device_reward_function`), checked once against ``compute_reward`` on the first
      relabelled batch;
    - else by the env's ``compute_reward`` on CPU copies of the goals (a gymnasium-robotics task, a reward wrapper such
      as :class:`~sb3_pilot.PilotBonusWrapper`, a ``SubprocVecEnv``): right, but it reads the batch back to the host.

    The semantics are SB3's (strategies, ``n_sampled_goal``, ``handle_timeout_termination``, episodes overwritten
    when the buffer wraps, ``truncate_last_trajectory``); the random draws are torch's, not numpy's. Saved (pickled)
    as numpy arrays, so a buffer saved from CUDA loads on a machine without it; it moves to ``buffer.device`` when
    next used (SB3's ``load_replay_buffer`` sets it to the model's).

    Memory per transition is SB3's: the observation and the next observation are both stored (SB3's HER buffer keeps
    ``next_observations`` apart: ``optimize_memory_usage`` is not supported), so a 64x64x3 frame costs 2 x 12 KiB =
    24 KiB, plus the goals, the action and 28 bytes of reward, done, timeout and episode bookkeeping (about 2.4 GiB for
    1e5 transitions). A buffer that would take more than ``MAX_DEVICE_MEMORY_FRACTION`` of a CUDA device's memory is
    refused, naming its size; on CPU, SB3's warning when host memory looks too small is the only check.

    :param args: positional arguments of SB3's ``HerReplayBuffer``
    :param storage: ``"host"`` (numpy arrays in host memory, SB3's) or ``"device"`` (torch tensors on ``device``)
    :param kwargs: keyword arguments of SB3's ``HerReplayBuffer``
    """

    #: class default, for instances made from SB3's buffer or pickled before storage existed
    storage: str = "host"

    def __init__(self, *args: Any, storage: str = "host", **kwargs: Any):
        if storage not in STORAGES:
            raise ValueError(f"storage must be one of {STORAGES}, got {storage!r}.")
        with warnings.catch_warnings():
            if storage == "device" and get_device(kwargs.get("device", "auto")).type == "cuda":
                # SB3 compares its arrays to the host memory; the tensors below live on the device
                warnings.filterwarnings("ignore", message="This system does not have apparently enough memory")
            super().__init__(*args, **kwargs)
        self.storage = storage
        if storage == "device":
            self._to_tensors(self.device)
            self._device_reward = self._resolve_device_reward(self.env)

    # ---------------------------------------- host storage (SB3's arrays)
    def sample(self, batch_size: int, env: VecNormalize | None = None) -> DictReplayBufferSamples:  # type: ignore[override]
        """
        :param batch_size: number of transitions
        :param env: the VecNormalize to normalise observations and rewards with, if any
        :return: the batch, its last ``int(her_ratio * batch_size)`` transitions with new goals and rewards
        """
        if self.storage == "device":
            self.prepare_draw(env)
            return self.draw(batch_size)
        # the transitions of finished episodes (ep_length > 0): until the buffer is full, only rows below pos can be,
        # so the scan stops there (SB3's scans all buffer_size rows per batch; same flat indices, same draws)
        is_valid = (self.ep_length if self.full else self.ep_length[: self.pos]) > 0
        if not np.any(is_valid):
            raise RuntimeError(self._EMPTY)
        sampled_indices = np.random.choice(np.flatnonzero(is_valid), size=batch_size, replace=True)
        batch_indices, env_indices = np.unravel_index(sampled_indices, is_valid.shape)
        # SB3 relabels the first n_virtual draws and puts them after the real ones
        n_virtual = int(self.her_ratio * batch_size)
        virtual_batch, virtual_env = batch_indices[:n_virtual], env_indices[:n_virtual]
        batch_indices = np.concatenate([batch_indices[n_virtual:], virtual_batch])
        env_indices = np.concatenate([env_indices[n_virtual:], virtual_env])
        virtual = slice(batch_size - n_virtual, batch_size)

        obs = {key: values[batch_indices, env_indices] for key, values in self.observations.items()}
        next_obs = {key: values[batch_indices, env_indices] for key, values in self.next_observations.items()}
        rewards = self.rewards[batch_indices, env_indices].astype(np.float32)
        if n_virtual > 0:
            new_goals = self._sample_goals(virtual_batch, virtual_env)
            obs["desired_goal"][virtual] = new_goals
            next_obs["desired_goal"][virtual] = new_goals
            # r_t = reward(s_{t+1}'s achieved goal, new desired goal)
            rewards[virtual] = self._compute_reward(next_obs["achieved_goal"][virtual], new_goals, virtual_batch, virtual_env)
        normalize_in_place(obs, env)
        normalize_in_place(next_obs, env)
        return DictReplayBufferSamples(
            observations={key: self.to_torch(values) for key, values in obs.items()},
            actions=self.to_torch(self.actions[batch_indices, env_indices]),
            next_observations={key: self.to_torch(values) for key, values in next_obs.items()},
            # dones that are not timeouts (SB3's handle_timeout_termination)
            dones=self.to_torch(
                self.dones[batch_indices, env_indices] * (1 - self.timeouts[batch_indices, env_indices])
            ).reshape(-1, 1),
            rewards=self.to_torch(self._normalize_reward(rewards.reshape(-1, 1), env)),
        )

    _EMPTY = (
        "Unable to sample before the end of the first episode. We recommend choosing a value "
        "for learning_starts that is greater than the maximum number of timesteps in the environment."
    )

    def _compute_reward(
        self, achieved_goals: np.ndarray, new_goals: np.ndarray, batch_indices: np.ndarray, env_indices: np.ndarray
    ) -> np.ndarray:
        """The env's ``compute_reward`` of relabelled transitions (SB3's call: the first env's method, their infos)."""
        infos = (
            copy.deepcopy(self.infos[batch_indices, env_indices])
            if self.copy_info_dict
            else [{} for _ in range(len(batch_indices))]
        )
        assert self.env is not None, "HerReplayBuffer needs its VecEnv to compute the rewards of relabelled goals"
        rewards = self.env.env_method("compute_reward", achieved_goals, new_goals, infos, indices=[0])[0]
        return np.asarray(rewards, dtype=np.float32)

    # ---------------------------------------- device storage
    def _to_tensors(self, device: th.device) -> None:
        """Hold the stored arrays as tensors on ``device`` (from numpy arrays or tensors elsewhere), after the cap check."""
        self._check_device_memory(device)

        def move(values: Any) -> th.Tensor:
            return th.as_tensor(values).to(device)

        self.observations = {key: move(values) for key, values in self.observations.items()}  # type: ignore[misc]
        self.next_observations = {key: move(values) for key, values in self.next_observations.items()}  # type: ignore[misc]
        for name in _STORED_ARRAYS:
            setattr(self, name, move(getattr(self, name)))
        # the bookkeeping stays in SB3's host arrays too: add() reads it there, without a device read per step
        self._ep_start_device = move(self.ep_start)
        self._ep_length_device = move(self.ep_length)
        self._storage_device = device
        self._n_valid = int(np.count_nonzero(self.ep_length))
        # VecNormalize's statistics, copied here before each draw (static tensors: a captured draw reads them)
        self._obs_stats: dict[str, th.Tensor] = {}
        self._reward_std = th.ones((), dtype=th.float64, device=device)
        self._normalization: tuple[Any, ...] | None = None
        self.storage_version = getattr(self, "storage_version", 0) + 1

    def _check_device_memory(self, device: th.device) -> None:
        """Refuse a buffer that would take more than ``MAX_DEVICE_MEMORY_FRACTION`` of a CUDA device's memory."""
        if device.type != "cuda":
            return
        n_bytes = self.storage_nbytes()
        total = th.cuda.get_device_properties(device).total_memory
        if n_bytes > MAX_DEVICE_MEMORY_FRACTION * total:
            raise ValueError(
                f"A device-resident replay buffer of {self.buffer_size * self.n_envs} transitions takes "
                f"{n_bytes / 2**30:.1f} GiB, more than {MAX_DEVICE_MEMORY_FRACTION:.0%} of the "
                f"{total / 2**30:.1f} GiB of {device}: choose a smaller buffer_size, or storage='host'."
            )

    def storage_nbytes(self) -> int:
        """Bytes of the stored transitions (observations, next observations, actions, rewards, dones, timeouts, episodes)."""
        n_bytes = sum(values.nbytes for values in (*self.observations.values(), *self.next_observations.values()))
        n_bytes += sum(getattr(self, name).nbytes for name in _STORED_ARRAYS)
        return int(n_bytes + self.ep_start.nbytes + self.ep_length.nbytes)

    def _resolve_device_reward(self, env: VecEnv | None) -> Callable[[th.Tensor, th.Tensor], th.Tensor] | None:
        self._device_reward_checked = False
        goal_space = self.observation_space.spaces["desired_goal"]
        return device_reward_function(env, int(np.prod(goal_space.shape)))

    def set_env(self, env: VecEnv) -> None:
        super().set_env(env)
        if self.storage == "device":
            self._device_reward = self._resolve_device_reward(env)

    def _on_storage_device(self) -> None:
        """Move the tensors where ``self.device`` says (SB3 sets it after loading a buffer), first."""
        if self._storage_device != self.device:
            self._to_tensors(self.device)

    def add(  # type: ignore[override]
        self,
        obs: dict[str, np.ndarray],
        next_obs: dict[str, np.ndarray],
        action: np.ndarray,
        reward: np.ndarray,
        done: np.ndarray,
        infos: list[dict[str, Any]],
    ) -> None:
        if self.storage == "host":
            super().add(obs, next_obs, action, reward, done, infos)
            return
        self._on_storage_device()
        pos = self.pos
        # an episode being overwritten can no longer be sampled (SB3's rule), on the host and on the device
        for env_idx in range(self.n_envs):
            length = self.ep_length[pos, env_idx]
            if length > 0:
                indices = np.arange(pos, self.ep_start[pos, env_idx] + length) % self.buffer_size
                self._set_episode_length(indices, env_idx, 0)
        self.ep_start[pos] = self._current_ep_start
        self._ep_start_device[pos] = th.as_tensor(self._current_ep_start)
        if self.copy_info_dict:
            self.infos[pos] = infos  # type: ignore[assignment]
        for key, values in self.observations.items():
            values[pos] = th.as_tensor(np.asarray(obs[key])).reshape(values.shape[1:])
        for key, values in self.next_observations.items():
            values[pos] = th.as_tensor(np.asarray(next_obs[key])).reshape(values.shape[1:])
        self.actions[pos] = th.as_tensor(np.asarray(action)).reshape(self.actions.shape[1:])  # type: ignore[call-overload]
        self.rewards[pos] = th.as_tensor(np.asarray(reward, dtype=np.float32))  # type: ignore[call-overload]
        self.dones[pos] = th.as_tensor(np.asarray(done, dtype=np.float32))  # type: ignore[call-overload]
        if self.handle_timeout_termination:
            timeouts = np.array([info.get("TimeLimit.truncated", False) for info in infos], dtype=np.float32)
            self.timeouts[pos] = th.as_tensor(timeouts)  # type: ignore[call-overload]
        self.pos += 1
        if self.pos == self.buffer_size:
            self.full = True
            self.pos = 0
        for env_idx in range(self.n_envs):
            if done[env_idx]:
                self._compute_episode_length(env_idx)

    def _set_episode_length(self, indices: np.ndarray, env_idx: int, length: int) -> None:
        """Write an episode's length at its indices, on the host and on the device, and count the valid transitions."""
        self._n_valid += (len(indices) if length > 0 else 0) - int(np.count_nonzero(self.ep_length[indices, env_idx]))
        self.ep_length[indices, env_idx] = length
        device_indices = th.as_tensor(indices, device=self._ep_length_device.device)
        self._ep_length_device[device_indices, env_idx] = length

    def _compute_episode_length(self, env_idx: int) -> None:
        if self.storage == "host":
            super()._compute_episode_length(env_idx)
            return
        # SB3's, the lengths written through _set_episode_length
        episode_start = self._current_ep_start[env_idx]
        episode_end = self.pos
        if episode_end < episode_start:
            episode_end += self.buffer_size
        indices = np.arange(episode_start, episode_end) % self.buffer_size
        self._set_episode_length(indices, env_idx, episode_end - episode_start)
        self._current_ep_start[env_idx] = self.pos

    @property
    def draws_in_graph(self) -> bool:
        """Whether :meth:`draw` reads nothing back to the host, so that a CUDA graph can capture it."""
        return (
            self.storage == "device"
            and self.device.type == "cuda"
            and (self.her_ratio == 0 or (self._device_reward is not None and self._device_reward_checked))
        )

    def prepare_draw(self, env: VecNormalize | None = None) -> tuple[Any, ...]:
        """
        The host side of a device draw: move the storage where ``device`` says, check that a finished episode is
        stored, copy ``VecNormalize``'s current statistics into the tensors :meth:`draw` reads.

        :param env: the VecNormalize to normalise observations and rewards with, if any
        :return: what a captured draw depends on besides the stored tensors (it changes when the storage moves, the
            env's normalisation is switched or its success threshold changed)
        """
        self._on_storage_device()
        if self._n_valid == 0:
            raise RuntimeError(self._EMPTY)
        obs_keys: tuple[str, ...] = ()
        if env is not None and env.norm_obs:
            assert isinstance(env.obs_rms, dict) and env.norm_obs_keys is not None
            obs_keys = tuple(env.norm_obs_keys)
            for key in obs_keys:
                # the mean and the std as VecNormalize._normalize_obs computes them, in float64
                stats = np.stack([env.obs_rms[key].mean, np.sqrt(env.obs_rms[key].var + env.epsilon)])
                if key not in self._obs_stats:
                    self._obs_stats[key] = th.empty(stats.shape, dtype=th.float64, device=self.device)
                self._obs_stats[key].copy_(th.as_tensor(stats))
        norm_reward = env is not None and env.norm_reward
        if norm_reward:
            assert env is not None
            self._reward_std.fill_(float(np.sqrt(env.ret_rms.var + env.epsilon)))
        clip = (env.clip_obs, env.clip_reward) if env is not None else None
        self._normalization = (obs_keys, norm_reward, clip)
        # a captured twin holds the env's threshold as a constant: a new threshold needs a new capture
        threshold = getattr(getattr(self._device_reward, "__self__", None), "distance_threshold", None)
        return (self.storage_version, self._normalization, threshold)

    def draw(self, batch_size: int) -> DictReplayBufferSamples:
        """
        A batch drawn on the device, after :meth:`prepare_draw`: the real transitions first, then the
        ``int(her_ratio * batch_size)`` relabelled ones. Without a host read where the rewards have a device twin.

        :param batch_size: number of transitions
        """
        device = self._ep_length_device.device
        is_valid = (self._ep_length_device > 0).reshape(-1)
        # the k-th valid transition is the first flat index whose inclusive count of valid ones exceeds k
        counts = th.cumsum(is_valid, dim=0)
        n_valid = counts[-1]
        draws = th.minimum((th.rand(batch_size, dtype=th.float64, device=device) * n_valid).long(), n_valid - 1)
        flat_indices = th.searchsorted(counts, draws, right=True)
        batch_indices, env_indices = flat_indices // self.n_envs, flat_indices % self.n_envs

        obs = {key: values[batch_indices, env_indices] for key, values in self.observations.items()}
        next_obs = {key: values[batch_indices, env_indices] for key, values in self.next_observations.items()}
        rewards = self.rewards[batch_indices, env_indices]
        n_virtual = int(self.her_ratio * batch_size)
        if n_virtual > 0:
            virtual = slice(batch_size - n_virtual, batch_size)
            virtual_batch, virtual_env = batch_indices[virtual], env_indices[virtual]
            new_goals = self._sample_goals_on_device(virtual_batch, virtual_env)
            obs["desired_goal"][virtual] = new_goals
            next_obs["desired_goal"][virtual] = new_goals
            rewards[virtual] = self._relabelled_rewards(
                next_obs["achieved_goal"][virtual], new_goals, virtual_batch, virtual_env
            )
        assert self._normalization is not None, "call prepare_draw() before draw()"
        obs_keys, norm_reward, clip = self._normalization
        for key in obs_keys:
            mean, std = self._obs_stats[key]
            obs[key] = ((obs[key].double() - mean) / std).clamp(-clip[0], clip[0]).float()
            next_obs[key] = ((next_obs[key].double() - mean) / std).clamp(-clip[0], clip[0]).float()
        rewards = rewards.reshape(-1, 1)
        if norm_reward:
            rewards = (rewards.double() / self._reward_std).clamp(-clip[1], clip[1]).float()
        return DictReplayBufferSamples(
            observations=obs,
            actions=self.actions[batch_indices, env_indices],
            next_observations=next_obs,
            dones=(self.dones[batch_indices, env_indices] * (1 - self.timeouts[batch_indices, env_indices])).reshape(-1, 1),
            rewards=rewards,
        )

    def _sample_goals_on_device(self, batch_indices: th.Tensor, env_indices: th.Tensor) -> th.Tensor:
        """SB3's ``_sample_goals`` on the device: next achieved goals of the same episode, by the strategy."""
        episode_start = self._ep_start_device[batch_indices, env_indices]
        episode_length = self._ep_length_device[batch_indices, env_indices]
        if self.goal_selection_strategy == GoalSelectionStrategy.FINAL:
            index_in_episode = episode_length - 1
        elif self.goal_selection_strategy == GoalSelectionStrategy.FUTURE:
            # inclusive, as SB3's: the transition's own next achieved goal can be drawn
            current = (batch_indices - episode_start) % self.buffer_size
            uniform = th.rand(len(batch_indices), dtype=th.float64, device=batch_indices.device)
            index_in_episode = th.minimum(current + (uniform * (episode_length - current)).long(), episode_length - 1)
        elif self.goal_selection_strategy == GoalSelectionStrategy.EPISODE:
            uniform = th.rand(len(batch_indices), dtype=th.float64, device=batch_indices.device)
            index_in_episode = th.minimum((uniform * episode_length).long(), episode_length - 1)
        else:
            raise ValueError(f"Strategy {self.goal_selection_strategy} for sampling goals not supported!")
        transition_indices = (index_in_episode + episode_start) % self.buffer_size
        return self.next_observations["achieved_goal"][transition_indices, env_indices]

    def _relabelled_rewards(
        self, achieved_goals: th.Tensor, new_goals: th.Tensor, batch_indices: th.Tensor, env_indices: th.Tensor
    ) -> th.Tensor:
        """Rewards of relabelled transitions: the env's torch twin, else its ``compute_reward`` on CPU copies."""
        if self._device_reward is not None and self._device_reward_checked:
            return self._device_reward(achieved_goals, new_goals)
        host_rewards = self._compute_reward(
            achieved_goals.cpu().numpy(), new_goals.cpu().numpy(), batch_indices.cpu().numpy(), env_indices.cpu().numpy()
        )
        rewards = th.as_tensor(host_rewards, device=achieved_goals.device)
        if self._device_reward is not None:
            # once, against compute_reward itself: a twin that differs is not used
            twin = self._device_reward(achieved_goals, new_goals)
            self._device_reward_checked = True
            if not th.equal(twin, rewards):
                warnings.warn(
                    f"The device twin of compute_reward differs from compute_reward on {int((twin != rewards).sum())} of "
                    f"{len(rewards)} relabelled goals: rewards are computed by compute_reward on CPU copies.",
                    stacklevel=2,
                )
                self._device_reward = None
        return rewards

    def __getstate__(self) -> dict[str, Any]:
        state = super().__getstate__()
        if self.storage == "device":
            # numpy arrays (loadable without CUDA); the device copies of the bookkeeping are rebuilt from the host's
            for name in ("observations", "next_observations"):
                state[name] = {key: values.cpu().numpy() for key, values in state[name].items()}
            for name in _STORED_ARRAYS:
                state[name] = state[name].cpu().numpy()
            for name in ("_ep_start_device", "_ep_length_device", "_obs_stats", "_reward_std", "_device_reward"):
                state.pop(name, None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        super().__setstate__(state)
        if self.storage == "device":
            self.device = get_device(self.device)  # CPU where the saving machine's CUDA is missing (SB3's rule)
            self._to_tensors(th.device("cpu"))
            self._device_reward = None
            self._device_reward_checked = False
