"""PixelGoalExtractor reads the image and the desired goal only; PixelGoalSACPolicy trains it by the critic's loss."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.preprocessing import preprocess_obs

from sb3_pilot.common.torch_layers import PixelGoalExtractor, PixelGoalSACPolicy

SIZE = 40  # the smallest round size NatureCNN's 8x8/4, 4x4/2, 3x3/1 convolutions accept


class ImageGoalEnv(gym.Env):
    """A point in [-1, 1]^2 drawn as a bright square on a SIZE x SIZE image; sparse goal reward (numpy, fast)."""

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012

    def __init__(self) -> None:
        box2 = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        image = spaces.Box(0, 255, shape=(SIZE, SIZE, 3), dtype=np.uint8)
        self.observation_space = spaces.Dict({"observation": image, "achieved_goal": box2, "desired_goal": box2})
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.position = np.zeros(2, dtype=np.float32)
        self.goal = np.zeros(2, dtype=np.float32)
        self.steps = 0

    def _obs(self) -> dict[str, np.ndarray]:
        image = np.zeros((SIZE, SIZE, 3), dtype=np.uint8)
        row, col = ((self.position + 1) / 2 * (SIZE - 4)).astype(int)
        image[row : row + 4, col : col + 4] = 255
        return {"observation": image, "achieved_goal": self.position.copy(), "desired_goal": self.goal.copy()}

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        return -(np.linalg.norm(achieved_goal - desired_goal, axis=-1) > 0.2).astype(np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        self.position = self.np_random.uniform(-1, 1, 2).astype(np.float32)
        self.goal = self.np_random.uniform(-1, 1, 2).astype(np.float32)
        self.steps = 0
        return self._obs(), {}

    def step(self, action: np.ndarray) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        self.position = np.clip(self.position + 0.2 * np.asarray(action, dtype=np.float32), -1, 1)
        self.steps += 1
        obs = self._obs()
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], {}))
        return obs, reward, False, self.steps >= 10, {"is_success": reward == 0.0}


def make_sac(encoder: str, seed: int = 0) -> SAC:
    return SAC(
        PixelGoalSACPolicy,
        ImageGoalEnv(),
        replay_buffer_class=HerReplayBuffer,
        buffer_size=1000,
        learning_starts=20,
        batch_size=16,
        policy_kwargs={"net_arch": [16, 16], "features_extractor_kwargs": {"encoder": encoder}},
        seed=seed,
        device="cpu",
    )


@pytest.mark.parametrize("encoder", ["nature", "paper"])
def test_features_ignore_achieved_goal(encoder: str) -> None:
    """Changing achieved_goal leaves the features unchanged; changing the image or the desired goal does not."""
    model = make_sac(encoder)
    extractor = model.policy.actor.features_extractor
    assert isinstance(extractor, PixelGoalExtractor) and extractor.encoder == encoder
    assert extractor.features_dim == (256 if encoder == "nature" else 50) + 2
    env = ImageGoalEnv()
    obs, _ = env.reset(seed=1)
    batch = model.policy.obs_to_tensor(obs)[0]

    def features(observation: dict[str, th.Tensor]) -> th.Tensor:
        with th.no_grad():
            return extractor(preprocess_obs(observation, model.policy.observation_space))

    reference = features(batch)
    moved = {**batch, "achieved_goal": batch["achieved_goal"] + 0.7}
    assert th.equal(features(moved), reference)
    other_goal = {**batch, "desired_goal": batch["desired_goal"] + 0.7}
    assert not th.allclose(features(other_goal), reference)
    other_image = {**batch, "observation": th.zeros_like(batch["observation"])}
    assert not th.allclose(features(other_image), reference)
    # the actions do not depend on achieved_goal either
    action, _ = model.predict(obs, deterministic=True)
    moved_action, _ = model.predict({**obs, "achieved_goal": obs["achieved_goal"] + 0.7}, deterministic=True)
    np.testing.assert_array_equal(action, moved_action)


def channel_first_space() -> spaces.Dict:
    """The observation space the extractor sees: SB3 transposes the image to channel-first."""
    space = ImageGoalEnv().observation_space
    image = spaces.Box(0, 255, shape=(3, SIZE, SIZE), dtype=np.uint8)
    return spaces.Dict({**space.spaces, "observation": image})


def test_paper_encoder_shapes() -> None:
    """4 conv 3x3 layers of 32 channels, strides 2, 1, 1, 1, then 50 units and LayerNorm."""
    extractor = PixelGoalExtractor(channel_first_space(), encoder="paper")
    convs = [layer for layer in extractor.cnn if isinstance(layer, th.nn.Conv2d)]
    assert [(conv.out_channels, conv.kernel_size, conv.stride) for conv in convs] == [
        (32, (3, 3), (stride, stride)) for stride in (2, 1, 1, 1)
    ]
    assert isinstance(extractor.head[1], th.nn.LayerNorm) and extractor.head[0].out_features == 50


def test_bad_arguments() -> None:
    space = channel_first_space()
    with pytest.raises(ValueError, match="Unknown encoder"):
        PixelGoalExtractor(space, encoder="resnet")
    with pytest.raises(ValueError, match="desired_goal"):
        PixelGoalExtractor(spaces.Dict({"observation": space["observation"]}))
    with pytest.raises(ValueError, match="shares its encoder"):
        SAC(PixelGoalSACPolicy, ImageGoalEnv(), policy_kwargs={"share_features_extractor": False}, buffer_size=10)


@pytest.mark.parametrize("encoder", ["nature", "paper"])
def test_shared_encoder_trained_by_the_critic_only(encoder: str) -> None:
    """One encoder for actor and critic, in the critic's optimizer only; training moves it; the target has a copy."""
    model = make_sac(encoder)
    policy = model.policy
    assert policy.actor.features_extractor is policy.critic.features_extractor
    assert policy.critic_target.features_extractor is not policy.critic.features_extractor
    encoder_params = {id(param) for param in policy.critic.features_extractor.parameters()}
    actor_params = {id(param) for group in policy.actor.optimizer.param_groups for param in group["params"]}
    critic_params = {id(param) for group in policy.critic.optimizer.param_groups for param in group["params"]}
    assert encoder_params <= critic_params and not encoder_params & actor_params
    # the actor's loss gives the encoder no gradient, through the actor or through the critic it calls
    obs = policy.obs_to_tensor(ImageGoalEnv().reset(seed=0)[0])[0]
    actions_pi, log_prob = policy.actor.action_log_prob(obs)
    q_pi = th.cat(policy.critic(obs, actions_pi), dim=1).min(dim=1).values
    (log_prob - q_pi).mean().backward()
    assert all(param.grad is None for param in policy.critic.features_extractor.parameters())
    assert any(param.grad is not None for param in policy.actor.mu.parameters())
    # the critic's loss does
    th.cat(policy.critic(obs, th.zeros_like(actions_pi)), dim=1).sum().backward()
    assert all(param.grad is not None for param in policy.critic.features_extractor.parameters())

    before = [param.detach().clone() for param in policy.critic.features_extractor.parameters()]
    model.learn(60)
    after = list(policy.critic.features_extractor.parameters())
    assert any(not th.equal(old, new) for old, new in zip(before, after, strict=True))


def test_save_load(tmp_path: Any) -> None:
    model = make_sac("paper")
    model.learn(30)
    model.save(tmp_path / "model.zip")
    loaded = SAC.load(tmp_path / "model.zip", env=ImageGoalEnv(), device="cpu")
    assert isinstance(loaded.policy, PixelGoalSACPolicy)
    assert loaded.policy.actor.features_extractor is loaded.policy.critic.features_extractor
    obs, _ = ImageGoalEnv().reset(seed=3)
    np.testing.assert_allclose(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])
