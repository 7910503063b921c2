"""
The encoder of the pixel-only agents (``Pilot/FetchReachImage-v0``, ``Pilot/ReacherImage-v0``):
:class:`PixelGoalExtractor`, a CNN on the image beside the desired goal (never the achieved goal), optionally behind
DrQ's :class:`RandomShift`.

In the paper (section 5 and its appendix), the image *is* the observation; ``achieved_goal`` is there for HER's
relabelling and the reward only. SB3's ``MultiInputPolicy`` (``CombinedExtractor``) would feed every key of the
Dict observation to the networks, ``achieved_goal`` included, which is all the state a reaching task needs.

The paper's encoder: 4 conv layers 3x3 with 32 channels and strides 2, 1, 1, 1, then a 50-unit linear layer and
LayerNorm, shared by actor and critic and trained by the critic's loss only (SAC-AE / DrQ style). SB3's own
``share_features_extractor=True`` does the opposite: the shared extractor is trained by the *actor's* loss only
(``ContinuousCritic.forward`` computes features under ``set_grad_enabled(False)`` and ``SACPolicy._build`` leaves the
extractor out of the critic's optimizer). :class:`~sb3_pilot.pixels.PixelGoalSACPolicy` therefore builds the sharing
itself.
"""

from __future__ import annotations

import torch as th
from gymnasium import spaces
from stable_baselines3.common.preprocessing import get_flattened_obs_dim, is_image_space
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

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
    (with :class:`~sb3_pilot.pixels.PixelGoalSACPolicy`) the target critic each see their own shifts of the
    observations and of the next observations; :class:`~sb3_pilot.sac.LeanSAC` encodes the observations once per
    gradient step, so its critic and actor see the same shift of them
    (:meth:`~sb3_pilot.pixels.PixelGoalSACPolicy.encode`); ``predict`` and evaluations see the frame as it is.

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
