"""HER sampling of the lean update: SB3's ``HerReplayBuffer`` with real and relabelled transitions gathered at once."""

import copy

import numpy as np
from stable_baselines3.common.type_aliases import DictReplayBufferSamples
from stable_baselines3.common.vec_env import VecNormalize
from stable_baselines3.her.her_replay_buffer import HerReplayBuffer


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


class LeanHerReplayBuffer(HerReplayBuffer):
    """
    SB3's ``HerReplayBuffer`` (same arguments, same storage, same samples for the same random state) whose ``sample``
    gathers the real and the relabelled transitions of a batch in one pass: one index gather, one in-place
    normalisation (no deep copy) and one tensor copy per observation key, where SB3's makes two of each and concatenates
    them. The batch holds the real
    transitions first, then the relabelled ones, as SB3's does.
    """

    def sample(self, batch_size: int, env: VecNormalize | None = None) -> DictReplayBufferSamples:  # type: ignore[override]
        """
        :param batch_size: number of transitions
        :param env: the VecNormalize to normalise observations and rewards with, if any
        :return: the batch, its last ``int(her_ratio * batch_size)`` transitions with new goals and rewards
        """
        # the transitions of finished episodes (ep_length > 0): until the buffer is full, only rows below pos can be,
        # so the scan stops there (SB3's scans all buffer_size rows per batch; same flat indices, same draws)
        is_valid = (self.ep_length if self.full else self.ep_length[: self.pos]) > 0
        if not np.any(is_valid):
            raise RuntimeError(
                "Unable to sample before the end of the first episode. We recommend choosing a value "
                "for learning_starts that is greater than the maximum number of timesteps in the environment."
            )
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
            infos = (
                copy.deepcopy(self.infos[virtual_batch, virtual_env])
                if self.copy_info_dict
                else [{} for _ in range(n_virtual)]
            )
            new_goals = self._sample_goals(virtual_batch, virtual_env)
            obs["desired_goal"][virtual] = new_goals
            next_obs["desired_goal"][virtual] = new_goals
            assert self.env is not None, "HerReplayBuffer needs its VecEnv to compute the rewards of relabelled goals"
            # r_t = reward(s_{t+1}'s achieved goal, new desired goal)
            rewards[virtual] = self.env.env_method(
                "compute_reward", next_obs["achieved_goal"][virtual], new_goals, infos, indices=[0]
            )[0]
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
