"""Tasks declare their goal space (``goal_space_id``); the planner's check reads it; the tasks do not import the method."""

import ast
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from goal_envs import PointGoalEnv
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_pilot import GoalPlanner, PilotBonusWrapper
from sb3_pilot.distill import env_goal_space, goal_map_between, shares_goal_space
from sb3_pilot.distill import goal_planner as planner_module
from sb3_pilot.distill.goal_planner import registered_goal_space
from sb3_pilot.envs import PILOT_ENV_IDS, register_envs

register_envs()
ENVS_DIR = Path(__file__).resolve().parents[1] / "sb3_pilot" / "envs"
METHOD_PACKAGES = ("sb3_pilot.distill", "sb3_pilot.transfer", "sb3_pilot.udpo", "sb3_pilot.sac")


def test_tasks_do_not_import_the_method() -> None:
    """The task modules import nothing of the stages (distill, transfer, udpo) and register nothing into them."""
    for path in ENVS_DIR.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom | ast.Import):
                modules = [node.module or ""] if isinstance(node, ast.ImportFrom) else [alias.name for alias in node.names]
                stages = [name for name in modules if name == "sb3_pilot" or name.startswith(METHOD_PACKAGES)]
                assert not stages, f"{path.name} imports {stages}"
    assert not any(task.startswith("Pilot/") for group in planner_module.SHARED_GOAL_SPACES for task in group)


def test_pilot_tasks_declare_their_goal_spaces() -> None:
    spaces = {task: registered_goal_space(task) for task in PILOT_ENV_IDS}
    assert all(isinstance(space, str) for space in spaces.values()), spaces
    groups = [  # the paper's transfer pairs: one goal space within a group, another in each group
        {"Pilot/FetchReach-v0", "Pilot/FetchReachHighDim-v0", "Pilot/FetchReachImage-v0"},
        {"Pilot/FetchPush-v0", "Pilot/FetchPushHighDim-v0"},
        {"Pilot/Reacher-v0", "Pilot/ReacherImage-v0"},
        {"Pilot/PointLocomotion-v0", "Pilot/AntLocomotion-v0", "Pilot/AntLocomotion-v1"},
        {"Pilot/Maze2D-v0", "Pilot/Maze2DCar-v0", "Pilot/AntMaze-v0", "Pilot/AntMaze-v1"},
    ]
    assert [len({spaces[task] for task in group}) for group in groups] == [1] * len(groups)
    assert len({spaces[next(iter(group))] for group in groups}) == len(groups)
    env = gym.make("Pilot/Maze2DCar-v0")  # read through the wrappers, and from a VecEnv
    assert env_goal_space(env) == env_goal_space(DummyVecEnv([lambda: env])) == spaces["Pilot/Maze2D-v0"]
    assert (
        shares_goal_space("Pilot/Maze2D-v0", "Pilot/Maze2DCar-v0")
        and goal_map_between("Pilot/Maze2D-v0", "Pilot/AntMaze-v0") is None
    )
    assert not shares_goal_space("Pilot/Maze2D-v0", "Pilot/PointLocomotion-v0")
    assert registered_goal_space("NoSuchTask-v0") is None and registered_goal_space("Pendulum-v1") is None


class DeclaringPointEnv(PointGoalEnv):
    """A user's task class that declares its goal space."""

    goal_space_id = "my-arena-xy"


class OtherDeclaringPointEnv(DeclaringPointEnv):
    pass


class ElsewherePointEnv(PointGoalEnv):
    goal_space_id = "another-arena-xy"


def test_planner_check_reads_the_declared_goal_space() -> None:
    """A planner records its source's goal space; a task declaring the same one passes the check, another fails."""
    planner = GoalPlanner(2, net_arch=[4], metadata={"source_task": "DeclaringPointEnv", "goal_space_id": "my-arena-xy"})
    assert planner.source_goal_space == "my-arena-xy"
    PilotBonusWrapper(OtherDeclaringPointEnv(), planner)
    for env in (ElsewherePointEnv(), PointGoalEnv()):
        with pytest.raises(
            ValueError, match=rf"goal space 'my-arena-xy'\), whose goal space is not that of '{type(env).__name__}'"
        ):
            PilotBonusWrapper(env, planner)
    bad = PointGoalEnv()
    bad.goal_space_id = 3
    with pytest.raises(TypeError, match="goal_space_id must be a string"):
        env_goal_space(bad)


def test_planners_saved_before_goal_spaces_still_plan_for_their_tasks(tmp_path: Path) -> None:
    """A planner file without ``goal_space_id`` nor ``teacher_algorithm`` (saved before them) loads, and its source task's
    registered declaration decides: a Maze2D planner plans for the car, not for open ground. Committed planners too."""
    GoalPlanner(2, net_arch=[8], metadata={"source_task": "Pilot/Maze2D-v0", "sb3_pilot_version": "0.1.0"}).save(
        tmp_path / "old.pt"
    )
    files = [tmp_path / "old.pt", *sorted((ENVS_DIR.parents[1] / "zoo_runs").glob("**/*.pt"))]
    car, ground = gym.make("Pilot/Maze2DCar-v0"), gym.make("Pilot/PointLocomotion-v0")
    for path in files:
        with warnings.catch_warnings():  # saved by another version
            warnings.simplefilter("ignore")
            planner = GoalPlanner.load(path)
        if planner.source_task != "Pilot/Maze2D-v0":
            continue
        assert planner.check_env(car) is None
        landmark = planner.predict(np.zeros(2, dtype=np.float32), np.ones(2, dtype=np.float32))
        assert landmark.shape == (2,) and np.isfinite(landmark).all()
        with pytest.raises(ValueError, match="not that of 'Pilot/PointLocomotion-v0'"):
            planner.check_env(ground)
