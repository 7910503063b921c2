"""What the image agents see: ImageFrameStack (the image entry only, HER unaffected) and the tasks' show_target."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from image_envs import SIZE, ImageGoalEnv
from rl_zoo3.utils import get_wrapper_class
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.env_util import make_vec_env

from sb3_pilot.common.wrappers import ImageFrameStack
from sb3_pilot.envs import register_envs
from sb3_pilot.envs.fetch import FetchEnv
from sb3_pilot.envs.reacher import ReacherEnv
from sb3_pilot.pixels import PixelGoalSACPolicy


def test_frame_stack_stacks_the_image_only() -> None:
    env = ImageFrameStack(ImageGoalEnv(), n_frames=3)
    assert env.observation_space["observation"].shape == (SIZE, SIZE, 9)
    assert env.observation_space["desired_goal"] == ImageGoalEnv().observation_space["desired_goal"]
    inner = env.unwrapped
    obs, _ = env.reset(seed=0)
    first = inner._obs()["observation"]
    assert env.observation_space.contains(obs)
    np.testing.assert_array_equal(obs["observation"], np.concatenate([first] * 3, axis=-1))  # filled at reset
    frames = [first] * 3
    for action in ([1.0, 0.0], [0.0, 1.0], [-1.0, -1.0]):
        obs, *_ = env.step(np.array(action, dtype=np.float32))
        frames.append(inner._obs()["observation"])
        np.testing.assert_array_equal(obs["observation"], np.concatenate(frames[-3:], axis=-1))  # oldest first
        np.testing.assert_array_equal(obs["achieved_goal"], inner.position)
        np.testing.assert_array_equal(obs["desired_goal"], inner.goal)
    assert not np.array_equal(frames[-1], frames[-2])  # the frames did change
    channel_first = ImageGoalEnv()
    channel_first.observation_space = spaces.Dict(
        {**channel_first.observation_space.spaces, "observation": spaces.Box(0, 255, (3, SIZE, SIZE), np.uint8)}
    )
    assert ImageFrameStack(channel_first, n_frames=2).observation_space["observation"].shape == (6, SIZE, SIZE)


def test_frame_stack_bad_input() -> None:
    for n_frames in (0, -2, 1.5):
        with pytest.raises(ValueError, match="n_frames >= 1"):
            ImageFrameStack(ImageGoalEnv(), n_frames=n_frames)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="image entry 'pixels'"):
        ImageFrameStack(ImageGoalEnv(), key="pixels")
    with pytest.raises(ValueError, match=r"stacks images.*'desired_goal'"):
        ImageFrameStack(ImageGoalEnv(), key="desired_goal")


def test_frame_stack_with_her_from_a_zoo_yaml() -> None:
    """From a YAML's env_wrapper; SAC + HER learns on the stacked frames; relabelled rewards stay compute_reward's."""
    wrapper = get_wrapper_class({"env_wrapper": [{"sb3_pilot.common.wrappers.ImageFrameStack": {"n_frames": 2}}]})
    vec_env = make_vec_env(ImageGoalEnv, n_envs=2, wrapper_class=wrapper, seed=0)
    model = SAC(
        PixelGoalSACPolicy,
        vec_env,
        replay_buffer_class=HerReplayBuffer,
        buffer_size=500,
        learning_starts=40,
        batch_size=16,
        policy_kwargs={"net_arch": [16], "features_extractor_kwargs": {"random_shift": 2}},
        seed=0,
        device="cpu",
    )
    assert model.policy.observation_space["observation"].shape == (6, SIZE, SIZE)  # channel-first after SB3
    model.learn(80)
    assert model._n_updates > 0
    samples = model.replay_buffer.sample(64, env=None)
    achieved, desired = samples.next_observations["achieved_goal"].numpy(), samples.observations["desired_goal"].numpy()
    rewards = vec_env.env_method("compute_reward", achieved, desired, None, indices=0)[0]
    np.testing.assert_array_equal(samples.rewards.numpy().ravel(), rewards)
    assert (samples.rewards == 0).any()  # some relabelled goals are reached
    assert samples.observations["observation"].shape == (64, 6, SIZE, SIZE)


def test_frame_stack_on_reacher_image() -> None:
    """The rendered task with a stacked image: HER samples and the reward as on the task itself."""
    register_envs()
    vec_env = make_vec_env(
        "Pilot/ReacherImage-v0", n_envs=1, env_kwargs={"image_size": 40}, wrapper_class=ImageFrameStack, seed=0
    )
    model = SAC(
        PixelGoalSACPolicy,
        vec_env,
        replay_buffer_class=HerReplayBuffer,
        buffer_size=200,
        learning_starts=100,
        batch_size=8,
        policy_kwargs={"net_arch": [16]},
        seed=0,
        device="cpu",
    )
    model.learn(110)
    samples = model.replay_buffer.sample(32, env=None)
    assert samples.observations["observation"].shape == (32, 9, 40, 40)
    achieved, desired = samples.next_observations["achieved_goal"].numpy(), samples.observations["desired_goal"].numpy()
    expected = -(np.linalg.norm(achieved - desired, axis=-1) > 0.02).astype(np.float32)
    np.testing.assert_array_equal(samples.rewards.numpy().ravel(), expected)


@pytest.mark.parametrize("task", ["reacher", "fetch"])
def test_show_target(task: str) -> None:
    """
    Same state, the target hidden: the frames differ in one small patch only, where the shown frame has all its red
    (target-coloured) pixels and the hidden one none; the goals are unchanged.
    """

    def make(show_target: bool) -> gym.Env:
        if task == "reacher":
            return ReacherEnv(image_size=64, show_target=show_target)
        return FetchEnv("reach", image_size=64, show_target=show_target)

    shown, hidden = make(True), make(False)
    for seed in (0, 1):
        frames = []
        for obs in (shown.reset(seed=seed)[0], hidden.reset(seed=seed)[0]):
            frames.append(obs["observation"].astype(int))
        action = np.full(shown.action_space.shape, 0.5, dtype=np.float32)
        obs_shown, obs_hidden = shown.step(action)[0], hidden.step(action)[0]
        np.testing.assert_array_equal(obs_shown["achieved_goal"], obs_hidden["achieved_goal"])
        np.testing.assert_array_equal(obs_shown["desired_goal"], obs_hidden["desired_goal"])
        frames += [obs_shown["observation"].astype(int), obs_hidden["observation"].astype(int)]
        for with_target, without in (frames[:2], frames[2:]):
            differ = np.any(with_target != without, axis=-1)
            rows, cols = np.nonzero(differ)
            assert len(rows) > 0 and np.ptp(rows) < 8 and np.ptp(cols) < 8  # one target-sized patch
            red = lambda image: (image[..., 0] > 120) & (image[..., 1] < 100) & (image[..., 2] < 100)  # noqa: E731
            assert red(with_target).any() and not (red(with_target) & ~differ).any() and not red(without).any()
    shown.close()
    hidden.close()


def test_fetch_frames_without_antialiasing() -> None:
    """
    antialias=False draws the same scene with one sample a pixel: same goals, most pixels identical, the others (the
    edges) a few levels apart on average; the default keeps the model's multisampling (Pilot/FetchReachImage-v0's
    frames). A vector task refuses the option.
    """
    smooth, sharp = FetchEnv("reach", image_size=64), FetchEnv("reach", image_size=64, antialias=False)
    assert smooth.model.vis.quality.offsamples > 0 and sharp.model.vis.quality.offsamples == 0
    action = np.array([0.5, -0.5, 0.5, 0.0], dtype=np.float32)
    for obs_smooth, obs_sharp in (
        (smooth.reset(seed=3)[0], sharp.reset(seed=3)[0]),
        (smooth.step(action)[0], sharp.step(action)[0]),
    ):
        np.testing.assert_array_equal(obs_smooth["achieved_goal"], obs_sharp["achieved_goal"])
        np.testing.assert_array_equal(obs_smooth["desired_goal"], obs_sharp["desired_goal"])
        difference = np.abs(obs_smooth["observation"].astype(int) - obs_sharp["observation"].astype(int)).max(axis=-1)
        # most pixels alike (> 75% identical), the rest a few levels apart on average: the edges
        assert (difference == 0).mean() > 0.75 and 0 < difference.mean() < 10, difference.mean()
    smooth.close()
    sharp.close()
    with pytest.raises(ValueError, match="antialias=False is an image task's option"):
        FetchEnv("reach", antialias=False)
