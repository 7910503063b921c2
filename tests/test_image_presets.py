"""The image presets (hyperparams/image/): the pixel recipe, explicit update settings, the replay memory they state."""

from __future__ import annotations

import importlib
import re
from typing import Any

import numpy as np
import yaml
from gymnasium import spaces

from sb3_pilot.experiments.zoo import _with_conf_file, hyperparams_dir
from sb3_pilot.pixels import PixelGoalExtractor, PixelGoalSACPolicy, RandomShift

IMAGE = hyperparams_dir() / "image"
IMAGE_TASKS = {"Pilot/ReacherImage-v0": "Pilot-Reacher-v0", "Pilot/FetchReachImage-v0": "Pilot-FetchReach-v0"}
#: bytes of one transition's frames in SB3's HerReplayBuffer: observation and next observation, uint8 64x64x3
FRAMES_BYTES = 2 * 64 * 64 * 3


def load(name: str) -> dict[str, dict[str, Any]]:
    return yaml.safe_load((IMAGE / name).read_text())


def test_recipe_settings() -> None:
    sac, pilot = load("sac.yml"), load("sac_pilot.yml")
    assert set(sac) == set(pilot) == set(IMAGE_TASKS)
    for env_id, params in sac.items():
        module, name = params["policy"].rsplit(".", 1)  # the class's path, or its former one (still importable)
        assert getattr(importlib.import_module(module), name) is PixelGoalSACPolicy, env_id
        assert {"batch_size", "train_freq", "gradient_steps", "buffer_size"} <= set(params), env_id
        policy_kwargs = eval(params["policy_kwargs"])  # as the zoo does
        observation_space = spaces.Dict(
            {
                "observation": spaces.Box(0, 255, (3, 64, 64), np.uint8),
                "achieved_goal": spaces.Box(-1, 1, (3,)),
                "desired_goal": spaces.Box(-1, 1, (3,)),
            }
        )
        extractor = PixelGoalExtractor(observation_space, **policy_kwargs["features_extractor_kwargs"])
        assert isinstance(extractor.augmentation, RandomShift) and extractor.augmentation.pad == 4, env_id
        # HER + PILoT: the same recipe, plus the bonus and the buffer that relabels it
        bonus = {"replay_buffer_class", "env_wrapper"}
        assert {key: value for key, value in pilot[env_id].items() if key not in bonus} == {
            key: value for key, value in params.items() if key not in bonus
        }, env_id
        ((wrapper, kwargs),) = pilot[env_id]["env_wrapper"][0].items()
        assert wrapper == "sb3_pilot.PilotBonusWrapper" and kwargs["beta"] == 1.0, env_id
        assert kwargs["planner"] == f"logs/planners/{IMAGE_TASKS[env_id]}.pt", env_id
        assert "PilotHerReplayBuffer" in pilot[env_id]["replay_buffer_class"], env_id


def test_stated_replay_memory() -> None:
    """The memory the files state (per transition, and in GiB on each buffer_size line) is the buffer's."""
    header = (IMAGE / "sac.yml").read_text()
    assert f"{FRAMES_BYTES // 1024} KiB" in header
    for name in ("sac.yml", "sac_pilot.yml"):
        lines = [line for line in (IMAGE / name).read_text().splitlines() if line.strip().startswith("buffer_size:")]
        assert len(lines) == len(IMAGE_TASKS), name
        for line in lines:
            size, gib = re.fullmatch(r"\s*buffer_size: (\d+)\s+# ([\d.]+) GiB of frames.*", line).groups()  # type: ignore[union-attr]
            assert float(gib) == round(int(size) * FRAMES_BYTES / 2**30, 1), line


def test_conf_file_resolved() -> None:
    argv = ["--algo", "sac", "--env", "Pilot/ReacherImage-v0", "--conf-file", "image/sac.yml"]
    assert _with_conf_file(argv)[-1] == str(IMAGE / "sac.yml")
