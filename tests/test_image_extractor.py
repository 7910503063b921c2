"""
PixelGoalExtractor reads the image and the desired goal only; PixelGoalSACPolicy trains it by the critic's loss;
RandomShift (DrQ's augmentation) acts in training only; the auxiliary goal prediction trains the encoder under LeanSAC.
"""

from __future__ import annotations

import base64
import copy
import json
import zipfile
from typing import Any

import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from image_envs import SIZE, ImageGoalEnv
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.logger import configure
from stable_baselines3.common.preprocessing import preprocess_obs
from stable_baselines3.common.torch_layers import CombinedExtractor

from sb3_pilot import pixels
from sb3_pilot.common.lean import StepHooks
from sb3_pilot.pixels import PixelGoalExtractor, PixelGoalSACPolicy, RandomShift
from sb3_pilot.sac import LeanSAC


def make_sac(
    encoder: str,
    seed: int = 0,
    random_shift: int = 0,
    algo: type[SAC] = SAC,
    goal_prediction: float = 0.0,
    **policy_kwargs: Any,
) -> SAC:
    return algo(
        PixelGoalSACPolicy,
        ImageGoalEnv(),
        replay_buffer_class=HerReplayBuffer,
        buffer_size=1000,
        learning_starts=20,
        batch_size=16,
        policy_kwargs={
            "net_arch": [16, 16],
            "features_extractor_kwargs": {"encoder": encoder, "random_shift": random_shift},
            "goal_prediction": goal_prediction,
            **policy_kwargs,
        },
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
    model = make_sac("paper", random_shift=3)
    model.learn(30)
    model.save(tmp_path / "model.zip")
    loaded = SAC.load(tmp_path / "model.zip", env=ImageGoalEnv(), device="cpu")
    assert isinstance(loaded.policy, PixelGoalSACPolicy)
    assert loaded.policy.actor.features_extractor is loaded.policy.critic.features_extractor
    # the augmentation is restored with the policy's kwargs, the target critic's copy included
    for extractor in (loaded.policy.actor.features_extractor, loaded.policy.critic_target.features_extractor):
        assert isinstance(extractor.augmentation, RandomShift) and extractor.augmentation.pad == 3
    obs, _ = ImageGoalEnv().reset(seed=3)
    np.testing.assert_allclose(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])


# ---------------------------------------- DrQ's random shift


def lit_positions(images: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
    """Row and column of the one lit pixel of each image's first channel."""
    flat = (images[:, 0] == 1.0).flatten(1).nonzero()[:, 1]
    return flat // images.shape[-1], flat % images.shape[-1]


def test_random_shift_moves_by_at_most_pad() -> None:
    """Each image moves by its own integer offset in [-pad, pad] per axis (each drawn); border pixels repeated."""
    pad, size, row, col = 4, 20, 10, 7
    shift = RandomShift(pad)
    images = th.zeros(2000, 3, size, size)
    images[:, :, row, col] = 1.0
    shifted = shift(images)
    assert shifted.shape == images.shape
    assert th.equal(shifted.sum(dim=(2, 3)), th.ones(2000, 3))  # one lit pixel: copied, not interpolated
    rows, cols = lit_positions(shifted)
    assert set((rows - row).tolist()) == set(range(-pad, pad + 1)) == set((cols - col).tolist())
    assert th.equal(shifted[:, 0], shifted[:, 2])  # every channel (e.g. stacked frames) shifted alike
    # replicate padding (DrQ's): a lit top row, moved down by k, fills rows 0..k; moved up, it leaves the frame
    top = th.zeros(2000, 1, size, size)
    top[:, :, 0] = 1.0
    lit_rows = shift(top)[:, 0].amax(dim=2)
    n_lit = lit_rows.sum(dim=1).long()
    assert set(n_lit.tolist()) == set(range(pad + 2))
    assert th.equal(lit_rows, (th.arange(size) < n_lit[:, None]).float())
    shift.eval()
    assert shift(images) is images


def test_random_shift_in_training_only() -> None:
    """
    predict (evaluation mode) is deterministic and unaugmented: the same actions as the same weights without the
    augmentation; in training mode the features of one frame differ between calls, the target critic's too.
    """
    augmented, plain = make_sac("paper", random_shift=4), make_sac("paper", seed=1)
    plain.policy.load_state_dict(augmented.policy.state_dict())  # no parameters added by the augmentation
    obs, _ = ImageGoalEnv().reset(seed=2)
    actions = [augmented.predict(obs, deterministic=True)[0] for _ in range(3)]
    for action in actions:
        np.testing.assert_array_equal(action, plain.predict(obs, deterministic=True)[0])

    policy = augmented.policy
    batch = {key: value.repeat(8, *[1] * (value.dim() - 1)) for key, value in policy.obs_to_tensor(obs)[0].items()}
    features = {
        "shared": lambda: policy.actor.extract_features(batch, policy.actor.features_extractor),
        "target": lambda: policy.critic_target.extract_features(batch, policy.critic_target.features_extractor),
    }
    with th.no_grad():
        policy.set_training_mode(True)
        for name, extract in features.items():
            first, second = extract(), extract()
            assert not th.allclose(first, second), name
            assert not th.allclose(first[0], first[1]), name  # one draw per sample, not per batch
        assert not policy.critic_target.training  # the target's networks stay in evaluation mode
        policy.set_training_mode(False)
        for name, extract in features.items():
            assert th.equal(extract(), extract()), name


@pytest.mark.parametrize("algo", [SAC, LeanSAC])
def test_random_shift_acts_in_train(algo: type[SAC], monkeypatch: pytest.MonkeyPatch) -> None:
    """SB3's and the lean train() shift the observations for the actor and the critic, the next ones for the target."""
    model = make_sac("nature", random_shift=2, algo=algo)
    model.learn(25)  # fill the buffer past learning_starts
    calls: list[tuple[int, bool]] = []
    forward = RandomShift.forward

    def counting(self: RandomShift, images: th.Tensor) -> th.Tensor:
        calls.append((id(self), self.training))
        return forward(self, images)

    monkeypatch.setattr(RandomShift, "forward", counting)
    model.train(gradient_steps=1, batch_size=8)
    shared = id(model.policy.critic.features_extractor.augmentation)
    target = id(model.policy.critic_target.features_extractor.augmentation)
    # SB3: actor(s), actor(s'), target(s'), critic(s, a), critic(s, pi(s)), each its own draw, all in training mode
    assert set(calls) == {(shared, True), (target, True)}
    # SB3: s for the actor, the critic and the actor's loss, s' for the actor and the target; lean: s once (encode)
    expected = {SAC: (4, 1), LeanSAC: (2, 1)}[algo]
    assert (calls.count((shared, True)), calls.count((target, True))) == expected
    calls.clear()
    model.predict(ImageGoalEnv().reset(seed=0)[0])
    assert calls == [(shared, False)]


def test_lean_pixel_step_encodes_observations_once() -> None:
    """
    LeanSAC encodes s once per step (DrQ-v2): from the same weights, batch and draws as SB3's SAC, the same critic
    and temperature step (the encoder included); the actor's loss reads the encoder from before the critic's update.
    """
    sac = make_sac("nature")
    sac.learn(40)
    lean = make_sac("nature", algo=LeanSAC)
    lean.set_parameters(copy.deepcopy(sac.get_parameters()))
    with th.no_grad():
        lean.log_ent_coef.copy_(sac.log_ent_coef)
    lean.replay_buffer, lean._current_progress_remaining = sac.replay_buffer, sac._current_progress_remaining
    lean.set_logger(configure(None, []))
    batch = sac.replay_buffer.sample(8)
    passes = []
    for model in (sac, lean):
        model.replay_buffer.sample = lambda *args, **kwargs: batch
        extractor = model.policy.critic.features_extractor
        handle = extractor.register_forward_hook(lambda module, inputs, output, model=model: passes.append(model))
        th.manual_seed(1)
        model.train(gradient_steps=1, batch_size=8)
        handle.remove()
    # the shared encoder (the target's copy aside): SB3 on s three times and s' once; lean on s and s' once each
    assert (passes.count(sac), passes.count(lean)) == (4, 2)
    for name, value in lean.policy.critic.state_dict().items():
        th.testing.assert_close(value, sac.policy.critic.state_dict()[name], rtol=1e-4, atol=1e-6, msg=name)
    for key in ("train/critic_loss", "train/ent_coef_loss"):
        assert lean.logger.name_to_value[key] == pytest.approx(sac.logger.name_to_value[key], rel=1e-4), key
    assert lean.logger.name_to_value["train/actor_loss"] != sac.logger.name_to_value["train/actor_loss"]


def test_random_shift_bad_input() -> None:
    """No image entry, a shift of half the frame or more, or a negative or fractional one: a clear error."""
    space = channel_first_space()
    for bad in (-1, SIZE // 2, 1.5):
        with pytest.raises(ValueError, match="random_shift must be a number of pixels"):
            PixelGoalExtractor(space, random_shift=bad)
    PixelGoalExtractor(space, random_shift=SIZE // 2 - 1)
    vector = spaces.Dict({**space.spaces, "observation": spaces.Box(-1.0, 1.0, shape=(5,))})
    with pytest.raises(ValueError, match=r"must be an image space.*random_shift augments it"):
        PixelGoalExtractor(vector, random_shift=4)


# ---------------------------------------- Auxiliary goal prediction


def test_goal_prediction_loss_trains_the_encoder_and_its_head(tmp_path: Any) -> None:
    """
    LeanSAC adds the weighted loss to the critic's: it is logged, equals its formula on the critic's batch, moves the
    head and the encoder, is saved with the policy; without it the critic has no head; SB3's SAC refuses to train it.
    """
    plain = make_sac("nature", algo=LeanSAC)
    assert plain.policy.critic.goal_head is None and plain.policy.goal_prediction == 0.0
    model = make_sac("nature", algo=LeanSAC, goal_prediction=2.0)
    policy = model.policy
    head = policy.critic.goal_head
    assert head is not None and (head.in_features, head.out_features) == (256, 2)
    critic_params = {id(param) for group in policy.critic.optimizer.param_groups for param in group["params"]}
    assert {id(param) for param in head.parameters()} <= critic_params
    # the loss on a batch: the head on the critic's image features against achieved_goal
    model.learn(30)
    batch = model.replay_buffer.sample(8, env=model._vec_normalize_env)
    policy.critic(batch.observations, batch.actions)
    image = policy.critic.extract_features(batch.observations, policy.critic.features_extractor)[:, :256]
    expected = ((head(image) - batch.observations["achieved_goal"]) ** 2).sum(dim=1).mean()
    th.testing.assert_close(policy.goal_prediction_loss(batch.observations), expected)
    with pytest.raises(RuntimeError, match="encoder-training pass on this batch"):
        policy.goal_prediction_loss({key: value[:3] for key, value in batch.observations.items()})
    # a training call logs it and moves the head
    before = [param.detach().clone() for param in head.parameters()]
    model.train(gradient_steps=2, batch_size=8)
    assert "train/goal_prediction_loss" in model.logger.name_to_value
    assert all(not th.equal(old, new) for old, new in zip(before, head.parameters(), strict=True))
    # saved with the policy's kwargs
    model.save(tmp_path / "model.zip")
    loaded = LeanSAC.load(tmp_path / "model.zip", env=ImageGoalEnv(), device="cpu")
    assert loaded.policy.goal_prediction == 2.0 and loaded.policy.step_hooks_attached
    for old, new in zip(head.parameters(), loaded.policy.critic.goal_head.parameters(), strict=True):
        assert th.equal(old, new)
    # SB3's SAC would ignore the loss: refused when training starts
    sb3 = make_sac("nature", goal_prediction=1.0)
    with pytest.raises(ValueError, match="needs an algorithm that adds its loss"):
        sb3.learn(30)


def test_goal_prediction_teaches_the_position() -> None:
    """With a large weight, a few hundred steps make the image features predict achieved_goal on new frames."""
    model = make_sac("nature", algo=LeanSAC, goal_prediction=10.0)
    model.learn(400)
    env = ImageGoalEnv()
    frames = [env.reset(seed=seed)[0] for seed in range(100, 160)]
    observations = model.policy.obs_to_tensor({key: np.stack([frame[key] for frame in frames]) for key in frames[0]})[0]
    model.policy.set_training_mode(False)
    with th.no_grad():
        image = model.policy.critic.extract_features(observations, model.policy.critic.features_extractor)[:, :256]
        error = (model.policy.critic.goal_head(image) - observations["achieved_goal"]).norm(dim=1)
    # the positions are uniform in [-1, 1]^2: predicting their mean would err by about 0.77 on average
    assert error.mean() < 0.4, error.mean()


def test_goal_prediction_bad_input() -> None:
    """A negative weight, another features extractor, or no achieved_goal to predict: a clear error."""
    with pytest.raises(ValueError, match="goal_prediction"):
        make_sac("nature", goal_prediction=-1.0)
    with pytest.raises(ValueError, match="reads PixelGoalExtractor's image features"):
        SAC(
            PixelGoalSACPolicy,
            ImageGoalEnv(),
            buffer_size=10,
            policy_kwargs={"features_extractor_class": CombinedExtractor, "goal_prediction": 1.0},
        )


# ---------------------------------------- The pixel module and the lean step's extension point


def test_lean_step_takes_the_pixel_policy_through_its_hooks() -> None:
    """LeanSAC calls a policy's StepHooks where it has them (the pixel policy), and no hook of any other policy."""
    pixel = make_sac("nature", algo=LeanSAC)
    assert isinstance(pixel.policy, StepHooks) and pixel._step_hooks is pixel.policy and pixel.policy.step_hooks_attached
    plain = LeanSAC("MultiInputPolicy", ImageGoalEnv(), buffer_size=10, policy_kwargs={"net_arch": [8]}, device="cpu")
    assert not isinstance(plain.policy, StepHooks) and plain._step_hooks is None
    # SB3's SAC never attaches them
    assert not make_sac("nature").policy.step_hooks_attached
    # the auxiliary losses the pixel policy contributes: none without goal prediction, the weighted one with it
    assert pixel.policy.critic_auxiliary_losses(None) == {}
    model = make_sac("nature", algo=LeanSAC, goal_prediction=2.0)
    model.learn(30)
    batch = model.replay_buffer.sample(8, env=model._vec_normalize_env)
    encoded = model.policy.encode(batch.observations)
    model.policy.critic(encoded, batch.actions)
    ((name, (weight, loss)),) = model.policy.critic_auxiliary_losses(encoded).items()
    assert (name, weight) == ("goal_prediction_loss", 2.0)
    th.testing.assert_close(loss, model.policy.goal_prediction_loss(batch.observations))


def test_former_paths_name_the_pixel_classes(tmp_path: Any) -> None:
    """
    The classes moved to sb3_pilot.pixels stay importable from sb3_pilot.common(.torch_layers), which the YAML entries
    name, and a model saved while the policy lived there (its pickled policy class names the old path) loads.
    """
    from sb3_pilot import common
    from sb3_pilot.common import torch_layers

    for name in ("PixelGoalExtractor", "PixelGoalSACPolicy", "RandomShift", "EncodedObservations"):
        assert getattr(torch_layers, name) is getattr(pixels, name), name
    assert common.PixelGoalSACPolicy is PixelGoalSACPolicy
    model = make_sac("nature", algo=LeanSAC)
    old_module = "sb3_pilot.common.torch_layers"
    PixelGoalSACPolicy.__module__ = old_module  # pickled by reference, as before the move
    try:
        model.save(tmp_path / "old.zip")
    finally:
        PixelGoalSACPolicy.__module__ = pixels.policies.__name__
    with zipfile.ZipFile(tmp_path / "old.zip") as archive:
        serialized = json.loads(archive.read("data"))["policy_class"][":serialized:"]
    assert old_module.encode() in base64.b64decode(serialized)
    loaded = LeanSAC.load(tmp_path / "old.zip", env=ImageGoalEnv(), device="cpu")
    assert type(loaded.policy) is PixelGoalSACPolicy and loaded._step_hooks is loaded.policy
    for old, new in zip(model.policy.parameters(), loaded.policy.parameters(), strict=True):
        assert th.equal(old, new)


# ---------------------------------------- The faster pixel step (issue 61): fused Adam, DrQ-v2's target as an option


def one_step(model: SAC, batch: Any, seed: int = 1) -> list[Any]:
    """Train ``model`` one gradient step on ``batch`` (seeded); the models whose encoders ran, one entry per pass."""
    model.replay_buffer.sample = lambda *args, **kwargs: batch
    model.set_logger(configure(None, []))
    passes: list[Any] = []
    extractors = {"shared": model.policy.critic.features_extractor, "target": model.policy.critic_target.features_extractor}
    handles = [
        extractor.register_forward_hook(lambda module, inputs, output, name=name: passes.append(name))
        for name, extractor in extractors.items()
    ]
    th.manual_seed(seed)
    model.train(gradient_steps=1, batch_size=len(batch.actions))
    for handle in handles:
        handle.remove()
    return passes


def twin(model: SAC, **policy_kwargs: Any) -> SAC:
    """A LeanSAC with ``model``'s weights, temperature and replay buffer, and other policy settings."""
    other = make_sac("nature", algo=LeanSAC, **policy_kwargs)
    other.set_parameters(copy.deepcopy(model.get_parameters()))
    with th.no_grad():
        other.log_ent_coef.copy_(model.log_ent_coef)
    other.replay_buffer, other._current_progress_remaining = model.replay_buffer, model._current_progress_remaining
    return other


def test_pixel_policy_adam_is_fused() -> None:
    """The pixel policy's optimizers are fused Adam (as the lean policies'), and step as the per-parameter Adam does."""
    model = make_sac("nature", algo=LeanSAC)
    assert model.actor.optimizer.defaults["fused"] and model.critic.optimizer.defaults["fused"]
    model.learn(40)
    plain = twin(model, optimizer_kwargs={"foreach": False})
    assert not plain.critic.optimizer.defaults["fused"]
    batch = model.replay_buffer.sample(8)
    for _ in range(3):  # Adam's moments in play from the second step on
        one_step(model, batch)
        one_step(plain, batch)
    for name, value in plain.policy.state_dict().items():
        th.testing.assert_close(model.policy.state_dict()[name], value, rtol=1e-5, atol=1e-6, msg=name)


def test_online_target_features_drqv2_target() -> None:
    """
    online_target_features: s' goes through the shared encoder once, for the actor and the target (2 passes a step,
    the target's copy unread). Where that copy equals the shared encoder and nothing is shifted, the step is the
    default one's; the option is saved with the policy, and SB3's SAC, which would ignore it, refuses to train.
    """
    model = make_sac("nature", algo=LeanSAC)
    model.learn(40)
    target, shared = model.policy.critic_target.features_extractor, model.policy.critic.features_extractor
    target.load_state_dict(shared.state_dict())
    online = twin(model, online_target_features=True)
    batch = model.replay_buffer.sample(8)
    assert sorted(one_step(model, batch)) == ["shared", "shared", "target"]
    assert one_step(online, batch) == ["shared", "shared"]
    for name, value in model.policy.critic.state_dict().items():
        th.testing.assert_close(online.policy.critic.state_dict()[name], value, rtol=1e-5, atol=1e-6, msg=name)
    assert online.logger.name_to_value["train/critic_loss"] == pytest.approx(
        model.logger.name_to_value["train/critic_loss"], rel=1e-5
    )
    # a target copy that lags: other targets
    other = twin(model, online_target_features=True)
    with th.no_grad():
        for param in other.policy.critic_target.features_extractor.parameters():
            param.mul_(0.5)
    reference = twin(model)
    reference.policy.critic_target.load_state_dict(other.policy.critic_target.state_dict())
    one_step(other, batch)
    one_step(reference, batch)
    losses = [model.logger.name_to_value["train/critic_loss"] for model in (other, reference)]
    assert losses[0] != pytest.approx(losses[1])
    assert online.policy._get_constructor_parameters()["online_target_features"]
    with pytest.raises(ValueError, match="online_target_features=True"):
        make_sac("nature", online_target_features=True).learn(25)
