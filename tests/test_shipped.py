"""
The files shipped for Zero-shot Ant-Maze load on a fresh clone and guide the Ant; the shipped Fetch-Reach and Fetch-Push
sources reach their goals; ``--reuse-shipped`` evaluates them.
"""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest

from sb3_pilot import GoalPlanner, LandmarkGuidance
from sb3_pilot.common.saved_models import vecnormalize_path
from sb3_pilot.envs import register_envs
from sb3_pilot.experiments.ant_controller import load_controller
from sb3_pilot.experiments.challenges import REUSE_SHIPPED, Shipped
from sb3_pilot.experiments.challenges.__main__ import main as challenges_main
from sb3_pilot.experiments.challenges.definitions import (
    FETCH_PUSH_SOURCE,
    FETCH_REACH_SOURCE,
    SHIPPED_V1_DIR,
    SOURCES_DIR,
    UMAZE_SHIPPED_DIR,
)
from sb3_pilot.experiments.challenges.stages import config_hash
from sb3_pilot.experiments.zoo import register
from sb3_pilot.experiments.zoo_run import load_zoo_model

register_envs()
SHIPPED_DIR = Path(__file__).resolve().parent.parent / "zoo_runs" / "zero-shot-ant-maze" / "controller"
CONTROLLERS = sorted(SHIPPED_DIR.glob("*.zip"))
PLANNERS = sorted(SHIPPED_DIR.glob("*.pt"))


def test_reuse_shipped_names_shipped_files():
    assert CONTROLLERS and PLANNERS
    for challenge in REUSE_SHIPPED.values():
        shipped = [stage.path for stage in challenge.stages if isinstance(stage, Shipped)]
        assert shipped and all(path.is_file() for path in shipped)
        assert all({SHIPPED_DIR, SHIPPED_V1_DIR, SOURCES_DIR, UMAZE_SHIPPED_DIR} & set(path.parents) for path in shipped)


def test_shipped_hash_covers_vecnormalize(tmp_path: Path):
    """A shipped zoo model's hash changes with its VecNormalize statistics, not only with its zip."""
    model = tmp_path / "Pilot-FetchReach-v0.zip"
    model.write_bytes(FETCH_REACH_SOURCE.read_bytes())
    stats = vecnormalize_path(model)

    def stage_hash() -> str:
        return config_hash(Shipped("source", model).config(ctx=None, stage_dir=tmp_path), [])  # no context is read

    alone = stage_hash()
    stats.parent.mkdir()
    stats.write_bytes(vecnormalize_path(FETCH_REACH_SOURCE).read_bytes())
    normalised = stage_hash()
    stats.write_bytes(b"other statistics")
    assert len({alone, normalised, stage_hash()}) == 3


@pytest.mark.parametrize("controller", CONTROLLERS, ids=lambda path: path.name)
@pytest.mark.parametrize("planner", PLANNERS, ids=lambda path: path.name)
def test_shipped_files_guide_the_ant(controller: Path, planner: Path):
    """Each shipped controller, guided by each shipped Maze2D planner, runs a short guided Ant-Maze episode."""
    model = load_controller(controller)
    goal_planner = GoalPlanner.load(planner)
    assert goal_planner.source_task == "Pilot/Maze2D-v0" and goal_planner.goal_dim == 2
    env = LandmarkGuidance(gym.make("Pilot/AntMaze-v0", max_episode_steps=20), goal_planner, horizon=3)
    observation, _ = env.reset(seed=0)
    for _ in range(20):
        action, _ = model.predict(observation, deterministic=True)
        observation, _, terminated, truncated, info = env.step(action)
    assert truncated and not terminated and env.action_space.contains(action.astype(np.float32))
    assert np.linalg.norm(info["landmark"] - observation["achieved_goal"]) < 4.0  # a landmark near the Ant
    env.close()


def test_shipped_umaze_models_guide_the_ant():
    """``pointmaze-to-antmaze --reuse-shipped``'s files: the SAC + HER teacher's planner, mapped to AntMaze's goals,
    guides the shipped open-arena controller on gymnasium-robotics' own U-maze from its far start."""
    register()  # gymnasium-robotics' tasks, as the challenge's stages register them
    challenge = REUSE_SHIPPED["pointmaze-to-antmaze"]
    shipped = {stage.name: stage.path for stage in challenge.stages if isinstance(stage, Shipped)}
    assert set(shipped) == {"distill", "chosen"}
    planner = GoalPlanner.load(shipped["distill"])
    assert planner.source_task == "PointMaze_UMaze-v3" and planner.metadata["teacher_algorithm"] == "SAC"
    (guided,) = [stage for stage in challenge.stages if getattr(stage, "planner", None) == "distill"]
    env = guided.make_env(ctx=SimpleNamespace(steps={guided.name: 20}, outputs=shipped))
    model, vec_normalize = load_zoo_model(shipped["chosen"], algo="sac")
    assert vec_normalize is None  # the controller's inputs are raw: its extractor makes them goal-relative
    observation, _ = env.reset(seed=0)
    first = observation["desired_goal"].copy()
    for _ in range(20):
        action, _ = model.predict(observation, deterministic=True)
        observation, _, terminated, truncated, info = env.step(action)
    assert truncated and not terminated
    real_goal = info["real_desired_goal"]
    assert np.linalg.norm(real_goal - observation["achieved_goal"]) > 4.0  # the far goal, round the U
    assert np.linalg.norm(first - observation["achieved_goal"]) < 4.0  # a landmark near the Ant instead
    env.close()


def test_reuse_shipped_smoke(tmp_path: Path):
    """The zero-shot evaluation of the shipped files: no training stage, k and the switch rule in summary.json."""
    challenges_main(["zero-shot-ant-maze", "--reuse-shipped", "--budget", "smoke", "--root", str(tmp_path), "--plot"])
    challenge = REUSE_SHIPPED["zero-shot-ant-maze"]
    run_dir = tmp_path / challenge.name
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["challenge"] == challenge.name and summary["seeds"] == [0]
    assert set(summary["stages"]) == {"seed_0/distill", "seed_0/controller", "seed_0/pilot"}
    shipped = "<repo>/zoo_runs/zero-shot-ant-maze/controller/"  # stored relative to the repository, as run folders are
    assert summary["stages"]["seed_0/controller"]["config"]["shipped"].startswith(shipped)
    assert summary["stages"]["seed_0/pilot"]["config"]["planner"].startswith(shipped)
    (method,) = summary["methods"].values()
    assert method["guidance"] == {
        "horizon": 1,
        "switch_distance": None,
        "switch_rule": "the real goal once it is closer than the landmark",
    }
    assert method["mean"]["timesteps"] == [0] and 0.0 <= method["mean"]["success_rate"][0] <= 1.0
    guidance = json.loads((run_dir / "models" / "seed_0" / "pilot" / "guidance.json").read_text())
    assert len(guidance["successes"]) == len(guidance["final_distances"]) == 2  # the smoke budget's episodes
    assert len(guidance["episodes"][0]["landmarks"]) == 51  # reset + 50 steps
    assert not list(run_dir.rglob("*.zip"))  # nothing trained, nothing copied
    assert (run_dir / "landmarks.png").stat().st_size > 10_000  # the shipped planner's landmarks, the guided Ant


def test_reuse_shipped_v1_smoke(tmp_path: Path):
    """The literature's-Ant shipped files: k chosen from the lead on the shipped planner, guided and unguided stages."""
    challenges_main(["zero-shot-ant-maze-v1", "--reuse-shipped", "--budget", "smoke", "--root", str(tmp_path)])
    run_dir = tmp_path / REUSE_SHIPPED["zero-shot-ant-maze-v1"].name
    summary = json.loads((run_dir / "summary.json").read_text())
    assert set(summary["stages"]) == {f"seed_0/{name}" for name in ("distill", "chosen", "pilot", "unguided")}
    guidance = json.loads((run_dir / "models" / "seed_0" / "pilot" / "guidance.json").read_text())
    assert guidance["horizon"] == 5  # the shipped planner's landmark ~2.75 ahead (its challenge seed's own k)
    assert len(guidance["episodes"][0]["landmarks"]) == 51


def test_shipped_v1_controller_refused_on_gymnasiums_ant():
    """The v1 controller ships with its zoo settings, so guiding it on a v0 (gymnasium's Ant) task is refused by name."""
    from sb3_pilot.experiments.challenges.controller import check_controller_ant

    controller = SHIPPED_V1_DIR / "ant_v1_controller_seed1_sac_200k.zip"
    env = gym.make("Pilot/AntMaze-v0")
    with pytest.raises(ValueError, match="trained on 'hrl'"):
        check_controller_ant(controller, env)
    check_controller_ant(controller, gym.make("Pilot/AntMaze-v1"))  # its own Ant: accepted
    env.close()


def test_reuse_shipped_only_where_shipped(tmp_path: Path):
    with pytest.raises(SystemExit):
        challenges_main(["vec-to-image", "--reuse-shipped", "--root", str(tmp_path)])


@pytest.mark.parametrize("source", [FETCH_REACH_SOURCE, FETCH_PUSH_SOURCE], ids=lambda path: path.stem)
def test_shipped_source_reaches(source: Path):
    """A shipped UDPO loads as the zoo saved it (its VecNormalize beside it) and reaches its goals on a fresh clone."""
    model, vec_normalize = load_zoo_model(source)  # on a DummyVecEnv of its task
    assert model.__class__.__name__ == "UDPO" and vec_normalize is not None and not vec_normalize.training
    successes = []
    vec_normalize.seed(0)
    observation = vec_normalize.reset()
    while len(successes) < 10:
        action, _ = model.predict(observation, deterministic=True)
        observation, _, dones, infos = vec_normalize.step(action)
        successes += [info["is_success"] for info, done in zip(infos, dones, strict=True) if done]
    assert np.mean(successes) >= 0.9


@pytest.mark.parametrize(
    "challenge, folder, net_arch",
    [("high-dim-action", "fetchreach_seed0", "[64, 64]"), ("high-dim-action-push", "fetchpush_seed0", "[256, 256]")],
)
def test_high_dim_action_reuse_shipped_smoke(tmp_path: Path, challenge: str, folder: str, net_arch: str):
    """High-Dim-Action from a shipped source: no source stage runs, the target reuses the shipped state planner at the
    source's network size (the smoke budget's own is 32x32)."""
    challenges_main([challenge, "--reuse-shipped", "--budget", "smoke", "--root", str(tmp_path)])
    run_dir = tmp_path / REUSE_SHIPPED[challenge].name
    summary = json.loads((run_dir / "summary.json").read_text())
    assert set(summary["stages"]) == {"seed_0/source", "seed_0/pilot", "seed_0/her"}
    shipped = f"<repo>/zoo_runs/sources/shipped/{folder}/"
    assert summary["stages"]["seed_0/source"]["config"]["shipped"].startswith(shipped)
    command = " ".join(summary["stages"]["seed_0/pilot"]["config"]["zoo"])
    assert "StatePlannerTransferCallback" in command and shipped in command and net_arch in command
    assert not list((run_dir / "models" / "seed_0" / "source").rglob("*.zip"))  # untrained
