"""
Features extractors (and the image policy) for the transfer targets, selectable from an RL-Zoo YAML's
``policy_kwargs`` / ``policy``:

- :class:`PixelGoalExtractor` and :class:`PixelGoalSACPolicy`: pixel-only agents for the image tasks (the image and
  the desired goal, never the achieved goal), trained the paper's way, optionally with DrQ's random shifts
  (:class:`RandomShift`) and an auxiliary loss that predicts the achieved goal from the image (``goal_prediction``);
- :class:`GoalRelativeExtractor`: translation- and heading-invariant features for a goal-conditioned controller
  (the zero-shot Ant-Maze controller), which then acts the same anywhere in a larger map.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import ContinuousCritic
from stable_baselines3.common.preprocessing import get_flattened_obs_dim, is_image_space
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.type_aliases import PyTorchObs
from stable_baselines3.sac.policies import Actor, SACPolicy
from torch import nn

from sb3_pilot.common.utils import check_number

# ---------------------------------------- Pixel-only image agents
# Pixel-only agents for the image tasks (``Pilot/FetchReachImage-v0``, ``Pilot/ReacherImage-v0``): a features
# extractor that reads the image and the desired goal, never the achieved goal, and a SAC policy that trains it as
# the paper does.
#
# In the paper (section 5 and its appendix), the image *is* the observation; ``achieved_goal`` is there for HER's
# relabelling and the reward only. SB3's ``MultiInputPolicy`` (``CombinedExtractor``) would feed every key of the
# Dict observation to the networks, ``achieved_goal`` included, which is all the state a reaching task needs.
#
# The paper's encoder: 4 conv layers 3x3 with 32 channels and strides 2, 1, 1, 1, then a 50-unit linear layer and
# LayerNorm, shared by actor and critic and trained by the critic's loss only (SAC-AE / DrQ style). SB3's own
# ``share_features_extractor=True`` does the opposite: the shared extractor is trained by the *actor's* loss only
# (``ContinuousCritic.forward`` computes features under ``set_grad_enabled(False)`` and ``SACPolicy._build`` leaves the
# extractor out of the critic's optimizer). :class:`PixelGoalSACPolicy` therefore builds the sharing itself.

#: Encoders of :class:`PixelGoalExtractor`.
ENCODERS = ("nature", "paper")
#: Keys of the Dict observation the extractor reads; ``achieved_goal`` is never read.
IMAGE_KEY, GOAL_KEY = "observation", "desired_goal"
#: The key the auxiliary goal prediction learns to predict (in training only: a target, never an input).
ACHIEVED_KEY = "achieved_goal"


def nature_cnn(n_channels: int) -> nn.Sequential:
    """SB3's ``NatureCNN`` convolutions (Mnih et al. 2015): 8x8/4 32, 4x4/2 64, 3x3/1 64, flattened."""
    return nn.Sequential(
        nn.Conv2d(n_channels, 32, kernel_size=8, stride=4),
        nn.ReLU(),
        nn.Conv2d(32, 64, kernel_size=4, stride=2),
        nn.ReLU(),
        nn.Conv2d(64, 64, kernel_size=3, stride=1),
        nn.ReLU(),
        nn.Flatten(),
    )


class RandomShift(nn.Module):
    """
    DrQ's image augmentation (Kostrikov et al., 2020): each image of the batch shifted by its own random integer
    offset of at most ``pad`` pixels along each axis, the border pixels repeated. The same as DrQ's replicate-pad by
    ``pad`` and random crop back to the frame's size, done as one ``gather`` over the batch (exact pixel copies, no
    interpolation). All channels of an image (e.g. stacked frames) get the same shift.

    It acts in training mode only: in evaluation mode (``predict``, evaluations) it returns its input.

    :param pad: the largest shift in pixels (DrQ's pad, 4 for 84x84 frames)
    """

    def __init__(self, pad: int):
        super().__init__()
        self.pad = pad

    def forward(self, images: th.Tensor) -> th.Tensor:
        """
        :param images: ``(batch, channels, height, width)`` images
        :return: the shifted images in training mode, else ``images``
        """
        if not self.training:
            return images
        n, c, h, w = images.shape
        shifts = th.randint(-self.pad, self.pad + 1, (2, n, 1), device=images.device)
        rows = (th.arange(h, device=images.device) + shifts[0]).clamp_(0, h - 1)
        cols = (th.arange(w, device=images.device) + shifts[1]).clamp_(0, w - 1)
        index = (rows[:, :, None] * w + cols[:, None, :]).view(n, 1, h * w).expand(n, c, h * w)
        return images.reshape(n, c, h * w).gather(2, index).view(n, c, h, w)

    def extra_repr(self) -> str:
        return f"pad={self.pad}"


def paper_cnn(n_channels: int) -> nn.Sequential:
    """The paper's convolutions (appendix, image encoder): 4 layers 3x3 with 32 channels, strides 2, 1, 1, 1."""
    layers: list[nn.Module] = []
    for stride in (2, 1, 1, 1):
        layers += [nn.Conv2d(n_channels, 32, kernel_size=3, stride=stride), nn.ReLU()]
        n_channels = 32
    return nn.Sequential(*layers, nn.Flatten())


class PixelGoalExtractor(BaseFeaturesExtractor):
    """
    Features of a goal-conditioned image observation: a CNN on ``observation`` (the image) concatenated with
    ``desired_goal`` as it is. ``achieved_goal`` (and any other key) is ignored.

    - ``encoder="nature"``: SB3's NatureCNN convolutions, then a linear layer of ``image_features`` units and a ReLU
      (as SB3's ``NatureCNN``; 256 units by default, as ``CombinedExtractor``'s ``cnn_output_dim``).
    - ``encoder="paper"``: the paper's convolutions, then a linear layer of ``image_features`` units (the paper's 50)
      and LayerNorm.

    With ``random_shift > 0``, the image is first shifted at random by up to that many pixels (:class:`RandomShift`,
    DrQ's augmentation) in training mode only, a new draw at every call: in SB3's ``SAC`` the critic, the actor and
    (with :class:`PixelGoalSACPolicy`) the target critic each see their own shifts of the observations and of the next
    observations; :class:`~sb3_pilot.sac.LeanSAC` encodes the observations once per gradient step, so its critic and
    actor see the same shift of them (:meth:`PixelGoalSACPolicy.encode`); ``predict`` and evaluations see the frame
    as it is.

    From a YAML: ``policy_kwargs: "dict(features_extractor_kwargs=dict(encoder='paper', random_shift=4))"``.

    :param observation_space: Dict with an image ``observation`` (channel-first, as SB3 transposes it) and
        ``desired_goal``
    :param encoder: ``"nature"`` or ``"paper"``
    :param image_features: size of the image embedding (None: 256 for ``nature``, 50 for ``paper``)
    :param normalized_image: whether images are already in [0, 1] (SB3's ``normalize_images=False``)
    :param random_shift: the largest random shift of the image in training, in pixels (DrQ: 4); 0: none. Less
        than half the image's side.
    """

    def __init__(
        self,
        observation_space: spaces.Dict,
        encoder: str = "nature",
        image_features: int | None = None,
        normalized_image: bool = False,
        random_shift: int = 0,
    ):
        if encoder not in ENCODERS:
            raise ValueError(f"Unknown encoder {encoder!r}, choose one of {ENCODERS}.")
        augmented = " (random_shift augments it)" if random_shift else ""
        if not isinstance(observation_space, spaces.Dict) or {IMAGE_KEY, GOAL_KEY} - set(observation_space.spaces):
            raise ValueError(
                f"PixelGoalExtractor needs a Dict observation space with an image {IMAGE_KEY!r}{augmented} and "
                f"{GOAL_KEY!r}, got {observation_space}."
            )
        image_space = observation_space[IMAGE_KEY]
        if not is_image_space(image_space, check_channels=False, normalized_image=normalized_image):
            raise ValueError(
                f"{IMAGE_KEY!r} must be an image space (channel-first after SB3's transpose){augmented}: {image_space}"
            )
        assert isinstance(image_space, spaces.Box)
        height, width = image_space.shape[1:]
        valid_int = isinstance(random_shift, int) and not isinstance(random_shift, bool)
        if not valid_int or not 0 <= 2 * random_shift < min(height, width):
            raise ValueError(
                f"random_shift must be a number of pixels >= 0 and less than half the side of the {height}x{width} "
                f"images, got {random_shift!r}."
            )
        image_features = image_features or (256 if encoder == "nature" else 50)
        goal_dim = get_flattened_obs_dim(observation_space[GOAL_KEY])
        super().__init__(observation_space, features_dim=image_features + goal_dim)
        self.encoder = encoder
        self.random_shift = random_shift
        # no parameters: the state dict (and loading models saved without it) is unchanged
        self.augmentation = RandomShift(random_shift) if random_shift else None
        n_channels = image_space.shape[0]
        self.cnn = (nature_cnn if encoder == "nature" else paper_cnn)(n_channels)
        with th.no_grad():
            n_flatten = self.cnn(th.as_tensor(image_space.sample()[None]).float()).shape[1]
        head: list[nn.Module] = [nn.Linear(n_flatten, image_features)]
        head.append(nn.ReLU() if encoder == "nature" else nn.LayerNorm(image_features))
        self.head = nn.Sequential(*head)

    def forward(self, observations: dict[str, th.Tensor]) -> th.Tensor:  # type: ignore[override]
        image = observations[IMAGE_KEY]
        if self.augmentation is not None:
            image = self.augmentation(image)
        features = self.head(self.cnn(image))
        return th.cat([features, th.flatten(observations[GOAL_KEY], start_dim=1)], dim=1)


@dataclass(frozen=True)
class EncodedObservations:
    """
    A batch of observations already through the shared encoder: ``phi(s)`` with its graph, as
    :meth:`PixelGoalSACPolicy.encode` returns it. The actor and the critic of :class:`PixelGoalSACPolicy` read it in
    place of the observations (the actor, and the critic at the actor's actions, without its gradient).

    :param observations: the batch ``s`` itself (its ``achieved_goal`` is the goal prediction's target)
    :param features: the features extractor's output (image features and desired goal), ``(batch, features_dim)``
    """

    observations: PyTorchObs
    features: th.Tensor


class _DetachedFeaturesActor(Actor):
    """SAC actor whose (shared) features extractor gets no gradient: its features are computed without one."""

    def extract_features(  # type: ignore[override]
        self, obs: PyTorchObs | EncodedObservations, features_extractor: BaseFeaturesExtractor
    ) -> th.Tensor:
        if isinstance(obs, EncodedObservations):
            return obs.features.detach()
        with th.no_grad():
            return super().extract_features(obs, features_extractor)


class _EncoderTrainingCritic(ContinuousCritic):
    """
    Critic that trains the features extractor it shares with the actor, from the critic's loss only.

    SB3's ``SAC.train`` calls the critic twice: on the replay actions for the critic's loss, then on the actor's
    actions (which require a gradient) for the actor's loss. Features get a gradient in the first call only, so
    the actor's loss, which the actor's optimizer minimises, never reaches the encoder (and its backward pass skips
    it, as DrQ's ``detach`` does).

    Given :class:`EncodedObservations` (features computed once, :meth:`PixelGoalSACPolicy.encode`), it reads them
    with their gradient in the same cases, detached otherwise.

    With a ``goal_head`` (:class:`PixelGoalSACPolicy`'s ``goal_prediction``), the image features of that first call
    are kept as ``image_features`` for the auxiliary loss of the same gradient step.
    """

    def __init__(self, *args: Any, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self.goal_head: nn.Linear | None = None
        self.image_features: th.Tensor | None = None

    def forward(self, obs: PyTorchObs | EncodedObservations, actions: th.Tensor) -> tuple[th.Tensor, ...]:
        trains_encoder = th.is_grad_enabled() and not actions.requires_grad
        if isinstance(obs, EncodedObservations):
            features = obs.features if trains_encoder else obs.features.detach()
        else:
            with th.set_grad_enabled(trains_encoder):
                features = self.extract_features(obs, self.features_extractor)
        if self.goal_head is not None and features.requires_grad:
            self.image_features = features[:, : self.goal_head.in_features]
        qvalue_input = th.cat([features, actions], dim=1)
        return tuple(q_net(qvalue_input) for q_net in self.q_networks)


class PixelGoalSACPolicy(SACPolicy):
    """
    SAC policy for the image tasks, the paper's way: one :class:`PixelGoalExtractor` (by default) shared by the actor
    and the critic, trained by the critic's loss only (it is in the critic's optimizer, not the actor's; the actor
    reads its features without gradient). The target critic has its own copy, updated by Polyak averaging with
    the critic's other weights and read without gradient, as in SB3.

    The extractor's :class:`RandomShift` (``random_shift``) follows the policy's training mode, the target critic's
    copy included (its networks stay in evaluation mode): in ``train()`` the target values are computed from shifted
    next observations, as in DrQ.

    With ``goal_prediction > 0``, the encoder also learns to predict the achieved goal ``g`` from the image: a linear
    head ``g_hat`` on the image features ``phi(o)`` of the critic's pass, and the critic's loss gets
    ``goal_prediction * mean ||g_hat(phi(o)) - g||^2`` (:meth:`goal_prediction_loss`; ``g`` as the agent's buffer holds
    it, standardised where the goal entries are normalised). The goal is a training target only: the actor and the
    critic still read the image and the desired goal alone. The pixel agent must locate its arm more finely than
    the success radius (Reacher-Image: 0.02, under 3 pixels), which the critic's sparse-reward loss alone teaches
    slowly. The loss is added by :class:`~sb3_pilot.sac.LeanSAC` (the zoo's ``lean_sac``); SB3's ``SAC`` would
    ignore it, so training with it refuses to start.

    In an RL-Zoo YAML: ``policy: sb3_pilot.common.torch_layers.PixelGoalSACPolicy``. Same parameters as SB3's
    ``MultiInputPolicy`` for SAC, but ``features_extractor_class`` defaults to :class:`PixelGoalExtractor` and
    ``share_features_extractor`` must stay True (the sharing described above).

    :param goal_prediction: weight of the auxiliary goal-prediction loss in the critic's loss (0: none)
    """

    #: set by the algorithm that adds :meth:`goal_prediction_loss` to its critic's loss (:class:`~sb3_pilot.sac.LeanSAC`)
    goal_prediction_trained: bool = False

    def __init__(
        self,
        *args: Any,
        features_extractor_class: type[BaseFeaturesExtractor] = PixelGoalExtractor,
        share_features_extractor: bool = True,
        goal_prediction: float = 0.0,
        **kwargs: Any,
    ):
        if not share_features_extractor:
            raise ValueError("PixelGoalSACPolicy shares its encoder between actor and critic: use MultiInputPolicy not to.")
        check_number("goal_prediction", goal_prediction, minimum=0.0)
        if goal_prediction and not issubclass(features_extractor_class, PixelGoalExtractor):
            raise ValueError(
                f"goal_prediction reads PixelGoalExtractor's image features; features_extractor_class is "
                f"{features_extractor_class.__name__}."
            )
        space = kwargs.get("observation_space", args[0] if args else None)
        if goal_prediction and (not isinstance(space, spaces.Dict) or ACHIEVED_KEY not in space.spaces):
            raise ValueError(f"goal_prediction predicts the observation's {ACHIEVED_KEY!r}, which it has not: {space}.")
        self.goal_prediction = float(goal_prediction)
        super().__init__(*args, features_extractor_class=features_extractor_class, share_features_extractor=True, **kwargs)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(goal_prediction=self.goal_prediction)
        return data

    def _build(self, lr_schedule: Any) -> None:
        self.actor = self.make_actor()
        self.critic = self.make_critic(features_extractor=self.actor.features_extractor)
        # the actor's optimizer leaves the shared encoder alone; the critic's trains it
        actor_parameters = [param for name, param in self.actor.named_parameters() if "features_extractor" not in name]
        self.actor.optimizer = self.optimizer_class(actor_parameters, lr=lr_schedule(1), **self.optimizer_kwargs)  # type: ignore[call-arg]
        self.critic.optimizer = self.optimizer_class(  # type: ignore[call-arg]
            self.critic.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs
        )
        self.critic_target = self.make_critic(features_extractor=None)
        self.critic_target.load_state_dict(self.critic.state_dict())
        self.critic_target.set_training_mode(False)
        self._target_augmentations = [module for module in self.critic_target.modules() if isinstance(module, RandomShift)]

    def set_training_mode(self, mode: bool) -> None:
        """SB3's switch of the actor's and the critic's mode, and of the target critic's augmentation (see above)."""
        if mode and self.goal_prediction and not self.goal_prediction_trained:
            raise ValueError(
                f"PixelGoalSACPolicy(goal_prediction={self.goal_prediction}) needs an algorithm that adds its loss: "
                "sb3_pilot.sac.LeanSAC (the zoo's lean_sac); SB3's SAC would train without it."
            )
        super().set_training_mode(mode)
        for augmentation in self._target_augmentations:
            augmentation.train(mode)

    def make_actor(self, features_extractor: BaseFeaturesExtractor | None = None) -> Actor:
        actor_kwargs = self._update_features_extractor(self.actor_kwargs, features_extractor)
        return _DetachedFeaturesActor(**actor_kwargs).to(self.device)

    def make_critic(self, features_extractor: BaseFeaturesExtractor | None = None) -> ContinuousCritic:
        critic_kwargs = self._update_features_extractor(self.critic_kwargs, features_extractor)
        critic = _EncoderTrainingCritic(**critic_kwargs)
        if self.goal_prediction:
            observation_space = self.observation_space
            assert isinstance(observation_space, spaces.Dict)
            image_features = critic.features_extractor.features_dim - get_flattened_obs_dim(observation_space[GOAL_KEY])
            critic.goal_head = nn.Linear(image_features, get_flattened_obs_dim(observation_space[ACHIEVED_KEY]))
        return critic.to(self.device)

    def encode(self, observations: PyTorchObs) -> EncodedObservations:
        """
        ``phi(s)``, once for a gradient step (DrQ-v2's order): the critic's encoder on the observations (shifted in
        training, with the gradient the critic's loss trains it by), which the actor, the critic and the actor's loss
        then read instead of encoding the batch three times. :class:`~sb3_pilot.sac.LeanSAC` calls it; the next
        observations are encoded as before (by the encoder for the actor, by the target's copy for the target).

        :param observations: the batch's observations ``s``
        :return: their features, for the actor's and the critic's calls of this gradient step
        """
        return EncodedObservations(observations, self.critic.extract_features(observations, self.critic.features_extractor))

    def goal_prediction_loss(self, observations: PyTorchObs | EncodedObservations) -> th.Tensor:
        """
        The auxiliary loss ``mean_batch ||g_hat(phi(o)) - g||^2`` of the critic's last encoder-training pass, which
        must have been on these observations (the critic's loss of the same gradient step).

        :param observations: the batch the critic was just called on (its ``achieved_goal`` is ``g``), or its encoding
        :return: the loss (a scalar with gradients for the encoder and the head)
        """
        if isinstance(observations, EncodedObservations):
            observations = observations.observations
        features = self.critic.image_features
        assert isinstance(observations, dict) and self.critic.goal_head is not None
        goals = observations[ACHIEVED_KEY].flatten(start_dim=1)
        if features is None or features.shape[0] != goals.shape[0]:
            raise RuntimeError("goal_prediction_loss needs the critic's encoder-training pass on this batch first.")
        return ((self.critic.goal_head(features) - goals) ** 2).sum(dim=1).mean()


# ---------------------------------------- Goal-relative controller features
# Features extractors for goal-conditioned policies (``policy_kwargs=dict(features_extractor_class=...)``).
#
# :class:`GoalRelativeExtractor` makes a goal-conditioned controller translation-invariant (and, for a robot with a
# free-floating torso such as the Ant, invariant to its heading): it drops the absolute position from the
# ``observation`` entry and feeds the goal relative to the achieved goal instead. The raw observations stay absolute,
# so the environment, HER's relabelling and the landmark guidance see the task unchanged; only what the networks
# read changes, and a controller trained around the origin acts the same anywhere in a larger map.
#
# From the RL Zoo's YAML (``policy_kwargs`` strings are evaluated without this package's names in scope)::
#
#     policy_kwargs: "dict(features_extractor_class=__import__('sb3_pilot.common.torch_layers',
#                     fromlist=['GoalRelativeExtractor']).GoalRelativeExtractor)"


def quaternion_yaw(quaternion: th.Tensor) -> th.Tensor:
    """
    :param quaternion: ``(..., 4)`` unit quaternions ``w, x, y, z`` (MuJoCo's order)
    :return: ``(...)`` yaw (rotation about the world z axis) of the body's x axis, in radians
    """
    w, x, y, z = quaternion.unbind(-1)
    return th.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def remove_yaw(quaternion: th.Tensor, yaw: th.Tensor) -> th.Tensor:
    """
    :param quaternion: ``(..., 4)`` quaternions ``w, x, y, z``
    :param yaw: ``(...)`` yaw angles
    :return: ``q_yaw^-1 * quaternion``: the same orientation seen from a frame turned by ``yaw`` about z
    """
    w, x, y, z = quaternion.unbind(-1)
    c, s = th.cos(yaw / 2), th.sin(yaw / 2)  # q_yaw^-1 = (c, 0, 0, -s)
    return th.stack((c * w + s * z, c * x + s * y, c * y - s * x, c * z - s * w), dim=-1)


def rotate_xy(vector: th.Tensor, angle: th.Tensor) -> th.Tensor:
    """
    :param vector: ``(..., 2)`` vectors
    :param angle: ``(...)`` angles
    :return: the vectors rotated by ``angle`` (counter-clockwise)
    """
    c, s = th.cos(angle), th.sin(angle)
    x, y = vector.unbind(-1)
    return th.stack((c * x - s * y, s * x + c * y), dim=-1)


class GoalRelativeExtractor(BaseFeaturesExtractor):
    """
    Translation-invariant features of a goal-conditioned ``Dict`` observation (``observation``, ``achieved_goal``,
    ``desired_goal``), where ``observation`` starts with the absolute position (``position_dim`` entries, the
    achieved goal's coordinates).

    Features: ``observation`` without its position, then the goal seen from the achieved goal,
    ``desired_goal - achieved_goal``, as its direction (unit vector) and its length clipped to
    ``max_goal_distance`` (a farther goal looks like one at that distance: what to do is walk towards it).

    With ``quaternion_index`` (planar goals of a free-floating torso, e.g. the Ant: 3, after x, y, z), everything
    is also turned into the torso's heading frame: the goal direction and the ``velocity_index`` xy velocity
    (world frame in MuJoCo's ``qvel``) are rotated by minus the torso's yaw and the torso's quaternion loses its
    yaw. The features are then the same for any position and heading of the same posture and motion.

    :param observation_space: the ``Dict`` observation space
    :param position_dim: number of leading ``observation`` entries holding the absolute position
    :param max_goal_distance: the goal's distance is clipped to it (None: not clipped)
    :param quaternion_index: index in ``observation`` of the torso's quaternion ``w, x, y, z`` (None: no
        heading frame; the Ant's is 3)
    :param velocity_index: index in ``observation`` of the torso's world-frame linear velocity (its x, y are
        rotated into the heading frame; the Ant's is 15)
    """

    def __init__(
        self,
        observation_space: gym.spaces.Dict,
        position_dim: int = 2,
        max_goal_distance: float | None = 3.0,
        quaternion_index: int | None = 3,
        velocity_index: int | None = 15,
    ):
        if not isinstance(observation_space, gym.spaces.Dict) or not {"observation", "achieved_goal", "desired_goal"} <= set(
            observation_space.spaces
        ):
            raise ValueError(
                f"GoalRelativeExtractor needs a goal-conditioned Dict observation space, got {observation_space}."
            )
        obs_dim = observation_space["observation"].shape[0]
        goal_dim = observation_space["desired_goal"].shape[0]
        if position_dim > obs_dim:
            raise ValueError(f"position_dim {position_dim} exceeds the observation size {obs_dim}.")
        if quaternion_index is not None:
            if goal_dim != 2:
                raise ValueError(f"The heading frame needs planar (2-dim) goals, got {goal_dim}-dim goals.")
            if quaternion_index < position_dim or quaternion_index + 4 > obs_dim:
                raise ValueError(f"quaternion_index {quaternion_index} does not fit the observation (size {obs_dim}).")
            if velocity_index is not None and (velocity_index < position_dim or velocity_index + 2 > obs_dim):
                raise ValueError(f"velocity_index {velocity_index} does not fit the observation (size {obs_dim}).")
        super().__init__(observation_space, features_dim=obs_dim - position_dim + goal_dim + 1)
        self.position_dim = position_dim
        self.max_goal_distance = max_goal_distance
        self.quaternion_index = quaternion_index
        self.velocity_index = velocity_index

    def forward(self, observations: dict[str, th.Tensor]) -> th.Tensor:
        observation = observations["observation"].float()
        delta = observations["desired_goal"].float() - observations["achieved_goal"].float()
        if self.quaternion_index is not None:
            observation = observation.clone()
            q_slice = slice(self.quaternion_index, self.quaternion_index + 4)
            yaw = quaternion_yaw(observation[:, q_slice])
            observation[:, q_slice] = remove_yaw(observation[:, q_slice], yaw)
            if self.velocity_index is not None:
                v_slice = slice(self.velocity_index, self.velocity_index + 2)
                observation[:, v_slice] = rotate_xy(observation[:, v_slice], -yaw)
            delta = rotate_xy(delta, -yaw)
        distance = th.linalg.vector_norm(delta, dim=-1, keepdim=True)
        direction = delta / distance.clamp_min(1e-6)
        if self.max_goal_distance is not None:
            distance = distance.clamp_max(self.max_goal_distance)
        return th.cat((observation[:, self.position_dim :], direction, distance), dim=-1)
