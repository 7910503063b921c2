"""The eleven Pilot/ tasks of the paper's Table 1 (run with MUJOCO_GL=osmesa for the image tasks)."""

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.env_checker import check_env
from stable_baselines3.common.preprocessing import is_image_space

from sb3_pilot.envs import (
    PILOT_ENV_IDS,
    UMAZE_MAP,
    UMAZE_SCALING,
    register_envs,
    umaze_cell_to_xy,
    umaze_is_free,
)

register_envs()

# id: (observation shape, observation dtype, action size, goal size, success distance, episode length)
TABLE_1 = {
    "Pilot/FetchReach-v0": ((10,), np.float32, 4, 3, 0.05, 50),
    "Pilot/FetchPush-v0": ((25,), np.float32, 4, 3, 0.05, 50),
    "Pilot/FetchReachHighDim-v0": ((10,), np.float32, 8, 3, 0.05, 50),
    "Pilot/FetchPushHighDim-v0": ((25,), np.float32, 8, 3, 0.05, 50),
    "Pilot/FetchReachImage-v0": ((64, 64, 3), np.uint8, 4, 3, 0.05, 50),
    "Pilot/Reacher-v0": ((11,), np.float32, 3, 2, 0.02, 50),
    "Pilot/ReacherImage-v0": ((64, 64, 3), np.uint8, 3, 2, 0.02, 50),
    "Pilot/PointLocomotion-v0": ((6,), np.float32, 2, 2, 0.1, 500),
    "Pilot/AntLocomotion-v0": ((29,), np.float32, 8, 2, 0.1, 100),
    "Pilot/Maze2D-v0": ((2,), np.float32, 2, 2, 1.0, 50),
    "Pilot/Maze2DCar-v0": ((4,), np.float32, 2, 2, 1.0, 50),  # beyond Table 1: the maze-car challenge's target
    "Pilot/AntMaze-v0": ((29,), np.float32, 8, 2, 1.0, 500),
    # beyond Table 1: the two Ant tasks with the hierarchical-RL literature's Ant
    "Pilot/AntLocomotion-v1": ((29,), np.float32, 8, 2, 0.1, 100),
    "Pilot/AntMaze-v1": ((29,), np.float32, 8, 2, 1.0, 500),
    # beyond Table 1: the wall-maze-car challenge's source and target
    "Pilot/WallMaze2D-v0": ((2,), np.float32, 2, 2, 0.1, 30),
    "Pilot/WallMaze2DCar-v0": ((4,), np.float32, 2, 2, 0.1, 30),
}


def test_registration_is_complete_idempotent_and_lazy():
    assert set(PILOT_ENV_IDS) == set(TABLE_1)
    register_envs()  # a second call is a no-op
    assert all(env_id in gym.registry for env_id in PILOT_ENV_IDS)
    code = "import sys, sb3_pilot.envs as e; e.register_envs(); assert 'mujoco' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("env_id", PILOT_ENV_IDS)
def test_task_matches_table_1(env_id):
    obs_shape, obs_dtype, act_dim, goal_dim, distance, episode = TABLE_1[env_id]
    env = gym.make(env_id)
    task = env.unwrapped

    # spaces
    spaces = env.observation_space.spaces
    assert set(spaces) == {"observation", "achieved_goal", "desired_goal"}
    assert spaces["observation"].shape == obs_shape and spaces["observation"].dtype == obs_dtype
    for key in ("achieved_goal", "desired_goal"):
        assert spaces[key].shape == (goal_dim,) and spaces[key].dtype == np.float32
    assert env.action_space.shape == (act_dim,)
    np.testing.assert_array_equal(env.action_space.low, -1.0)
    np.testing.assert_array_equal(env.action_space.high, 1.0)
    assert task.distance_threshold == distance
    assert env.spec.max_episode_steps == episode
    if obs_dtype == np.uint8:
        assert is_image_space(spaces["observation"])  # SB3 transposes it for its CNN policies

    check_env(task)

    # reproducible resets
    first, _ = env.reset(seed=3)
    second, _ = env.reset(seed=3)
    for key in first:
        np.testing.assert_array_equal(first[key], second[key])

    # one full episode: truncated at the table's length, never terminated; rewards = compute_reward
    env.action_space.seed(0)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    achieved, desired, rewards, successes = [], [], [], []
    for step in range(1, episode + 1):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert not terminated
        assert truncated == (step == episode)
        achieved.append(obs["achieved_goal"])
        desired.append(obs["desired_goal"])
        rewards.append(reward)
        successes.append(info["is_success"])
    assert env.observation_space.contains(obs)
    batch = task.compute_reward(np.array(achieved), np.array(desired), np.array([{}] * episode))
    assert batch.shape == (episode,)
    np.testing.assert_array_equal(batch, rewards)
    np.testing.assert_array_equal(np.array(rewards) == 0, successes)
    assert set(rewards) <= {-1.0, 0.0}

    # success exactly at the table's distance, on batches and single goals
    goal = np.zeros(goal_dim)
    offsets = np.zeros((4, goal_dim))
    offsets[:, 0] = [distance * (1 - 1e-4), distance, distance * (1 + 1e-4), 2 * distance]
    np.testing.assert_array_equal(task.compute_reward(offsets, np.tile(goal, (4, 1)), None), [0, 0, -1, -1])
    assert task.compute_reward(offsets[1], goal, {}) == 0
    assert task.compute_reward(offsets[2], goal, {}) == -1
    env.close()


def test_bad_input():
    with pytest.raises(TypeError, match="colour"):
        gym.make("Pilot/Maze2D-v0", colour="red")
    with pytest.raises(ValueError, match="image_size"):
        gym.make("Pilot/ReacherImage-v0", image_size=8)
    with pytest.raises(ValueError, match="render_mode"):
        gym.make("Pilot/FetchReachImage-v0", render_mode="human")
    with pytest.raises(ValueError, match="goal_distribution"):
        gym.make("Pilot/Maze2D-v0", goal_distribution="nearby")
    with pytest.raises(ValueError, match="task"):
        gym.make("Pilot/FetchReach-v0", task="slide")


def test_missing_renderer_says_how_to_fix_it(monkeypatch):
    def no_gl(width, height):
        raise AttributeError("'NoneType' object has no attribute 'glGetError'")

    monkeypatch.setattr("mujoco.gl_context.GLContext", no_gl)
    with pytest.raises(RuntimeError, match="install libosmesa6 and set MUJOCO_GL=osmesa"):
        gym.make("Pilot/ReacherImage-v0")


def test_high_dim_applies_h_and_80_percent_gravity():
    from sb3_pilot.envs.fetch import high_dim_action_transform

    e = np.e
    actions = np.array([np.zeros(8), [-1.0] * 4 + [0.5] * 4, [-1.0] * 4 + [1.0] * 4, [1.0] * 4 + [-1.0] * 4])
    expected = np.array([[-1.0] * 4, [(np.exp(0.5) - 1) / 1.5] * 4, [1.0] * 4, [-1.0] * 4])
    assert (1 - e) / 1.5 < -1 and (e - 1) / 1.5 > 1  # h(0) and h(-1, 1) are clipped
    np.testing.assert_allclose(high_dim_action_transform(actions), expected)

    source = gym.make("Pilot/FetchPush-v0").unwrapped
    target = gym.make("Pilot/FetchPushHighDim-v0").unwrapped
    # the robot receives h(a)
    received = []
    fetch_step = target.fetch.step
    target.fetch.step = lambda action: received.append(action) or fetch_step(action)
    target.reset(seed=0)
    action = np.linspace(-1, 1, 8)
    target.step(action)
    np.testing.assert_allclose(received[0], high_dim_action_transform(action))
    # free fall of the object, lifted above the table: 80% of the source's acceleration
    import mujoco

    falls = []
    for task in (source, target):
        task.reset(seed=0)
        model, data = task.model, task.data
        qpos_adr = model.jnt_qposadr[model.joint("object0:joint").id]
        data.qpos[qpos_adr + 2] += 0.3
        data.qvel[:] = 0.0
        mujoco.mj_step(model, data)
        falls.append(data.qvel[model.jnt_dofadr[model.joint("object0:joint").id] + 2] / model.opt.timestep)
    assert falls[0] == pytest.approx(-9.81, rel=1e-3)
    assert falls[1] == pytest.approx(0.8 * falls[0], rel=1e-6)


@pytest.mark.parametrize(
    ("env_id", "action"), [("Pilot/FetchReachImage-v0", [1, 1, 0, 0]), ("Pilot/ReacherImage-v0", [1, 1, 1])]
)
def test_image_changes_when_the_arm_moves(env_id, action):
    env = gym.make(env_id)
    before, _ = env.reset(seed=0)
    after = before
    for _ in range(5):
        after, *_ = env.step(np.array(action, dtype=np.float32))
    assert before["desired_goal"].tolist() == after["desired_goal"].tolist()
    changed = np.any(before["observation"] != after["observation"], axis=-1).mean()
    assert changed > 0.01, f"only {changed:.2%} of the pixels changed"
    assert after["observation"].std() > 10  # not a blank frame
    env.close()


def test_image_envs_render_their_own_scene_when_several_share_a_process():
    first = gym.make("Pilot/FetchReachImage-v0")
    reference = first.reset(seed=0)[0]["observation"]
    second = gym.make("Pilot/FetchReachImage-v0")
    second.close()  # the context created last is gone: first must still draw into its own
    np.testing.assert_array_equal(first.reset(seed=0)[0]["observation"], reference)
    third = gym.make("Pilot/FetchReachImage-v0")
    first.close()  # freeing first's GPU objects must not free third's
    np.testing.assert_array_equal(third.reset(seed=0)[0]["observation"], reference)
    third.close()


def test_umaze_matches_antmaze():
    from gymnasium_robotics.envs.maze.maps import U_MAZE

    assert [list(row) for row in UMAZE_MAP] == U_MAZE
    ant_maze = gym.make("Pilot/AntMaze-v0").unwrapped
    maze = ant_maze.maze_env.maze
    assert maze.maze_size_scaling == UMAZE_SCALING
    for row, col in zip(*np.nonzero(np.array(UMAZE_MAP) == 0), strict=True):
        np.testing.assert_allclose(umaze_cell_to_xy((row, col)), maze.cell_rowcol_to_xy(np.array([row, col])))

    # the walls of the MuJoCo AntMaze, as boxes in the plane
    model = ant_maze.model
    blocks = [model.geom(i) for i in range(model.ngeom) if model.geom(i).name.startswith("block_")]
    assert len(blocks) == int(np.sum(UMAZE_MAP))
    centers = np.array([block.pos[:2] for block in blocks])
    halves = np.array([block.size[:2] for block in blocks])

    def in_antmaze_wall(xy):
        return np.any(np.all(np.abs(xy[..., None, :] - centers) < halves, axis=-1), axis=-1)

    points = np.random.default_rng(0).uniform(-10, 10, size=(5000, 2))
    np.testing.assert_array_equal(umaze_is_free(points), ~in_antmaze_wall(points))
    corridor, wall = np.array([[0.0, 4.0], [4.0, 0.0], [-5.5, -5.5]]), np.array([[-3.0, 0.5], [0.0, 8.0], [9.0, 9.0]])
    assert umaze_is_free(corridor).all() and not in_antmaze_wall(corridor).any()
    assert not umaze_is_free(wall).any() and in_antmaze_wall(wall).all()

    # Maze2D positions (landmarks) never enter an AntMaze wall
    env = gym.make("Pilot/Maze2D-v0")
    env.reset(seed=0)
    env.action_space.seed(0)
    positions = [env.step(env.action_space.sample())[0]["observation"] for _ in range(2000)]
    assert not in_antmaze_wall(np.array(positions, dtype=np.float64)).any()


def test_maze2d_and_antmaze_share_start_and_goal():
    maze2d, ant_maze = gym.make("Pilot/Maze2D-v0"), gym.make("Pilot/AntMaze-v0")
    for seed in range(5):
        point_obs, _ = maze2d.reset(seed=seed)
        ant_obs, _ = ant_maze.reset(seed=seed)
        np.testing.assert_array_equal(point_obs["desired_goal"], ant_obs["desired_goal"])
        np.testing.assert_allclose(point_obs["achieved_goal"], ant_obs["achieved_goal"], atol=1e-6)
        assert np.abs(point_obs["achieved_goal"] - umaze_cell_to_xy((1, 1))).max() <= 1.0
        assert np.abs(point_obs["desired_goal"] - umaze_cell_to_xy((3, 1))).max() <= 1.0


def test_maze2d_far_goal_is_reachable_in_one_episode():
    env = gym.make("Pilot/Maze2D-v0")
    for seed in range(10):
        obs, _ = env.reset(seed=seed)
        waypoints = [np.array([2.5, 2.5]), np.array([2.5, -2.5]), obs["desired_goal"]]
        success = False
        while not success:
            if np.abs(obs["observation"] - waypoints[0]).max() < 1e-3 and len(waypoints) > 1:
                waypoints.pop(0)
            obs, _, _, truncated, info = env.step(np.clip((waypoints[0] - obs["observation"]) / 0.5, -1, 1))
            success = info["is_success"]
            assert success or not truncated, f"seed {seed}: far goal not reached in 50 steps"


def test_maze2d_walls_stop_the_point():
    env = gym.make("Pilot/Maze2D-v0").unwrapped
    env.reset(seed=0)
    env.position = np.array([-4.0, 2.3])  # just above the inner wall, whose top face is y = 2
    obs, *_ = env.step(np.array([1.0, -1.0]))
    np.testing.assert_allclose(obs["observation"], [-3.5, 2.0])  # slides along the wall
    env.position = np.array([5.8, 0.0])
    obs, *_ = env.step(np.array([1.0, 0.0]))
    np.testing.assert_allclose(obs["observation"], [6.0, 0.0])  # stops at the outer wall


def test_locomotion_tasks_share_goals():
    from sb3_pilot.envs.locomotion import LOCOMOTION_GOAL_RADIUS

    point, ant = gym.make("Pilot/PointLocomotion-v0"), gym.make("Pilot/AntLocomotion-v0")
    for seed in range(5):
        point_obs, _ = point.reset(seed=seed)
        ant_obs, _ = ant.reset(seed=seed)
        np.testing.assert_array_equal(point_obs["desired_goal"], ant_obs["desired_goal"])
        np.testing.assert_array_equal(point_obs["achieved_goal"], [0, 0])
        np.testing.assert_array_equal(ant_obs["achieved_goal"], [0, 0])
        assert np.linalg.norm(point_obs["desired_goal"]) <= LOCOMOTION_GOAL_RADIUS


def test_point_moves_along_its_heading():
    env = gym.make("Pilot/PointLocomotion-v0")
    env.reset(seed=0)
    obs, *_ = env.step(np.array([1.0, 0.0]))
    np.testing.assert_allclose(obs["observation"], [0.05, 0, 1, 0, 1.0, 0], atol=1e-6)  # 0.05 per 0.05 s step
    obs, *_ = env.step(np.array([1.0, 1.0]))  # turn 0.25 rad, then move
    np.testing.assert_allclose(obs["observation"][2:4], [np.cos(0.25), np.sin(0.25)], atol=1e-6)
    np.testing.assert_allclose(obs["achieved_goal"], [0.05 + 0.05 * np.cos(0.25), 0.05 * np.sin(0.25)], atol=1e-6)


@pytest.mark.parametrize(("version", "gear", "timestep"), [("v0", 150, 0.01), ("v1", 30, 0.02)])
def test_ant_is_the_same_model_in_both_ant_tasks(version, gear, timestep):
    loco = gym.make(f"Pilot/AntLocomotion-{version}").unwrapped
    maze = gym.make(f"Pilot/AntMaze-{version}").unwrapped
    a, b = loco.model, maze.model
    assert (a.nq, a.nv, a.nu, a.nbody) == (b.nq, b.nv, b.nu, b.nbody) == (15, 14, 8, 14)
    for field in ("actuator_gear", "actuator_ctrlrange", "body_mass", "body_inertia", "jnt_range", "dof_damping"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
    assert a.opt.timestep == b.opt.timestep and loco.frame_skip == maze.ant_env.frame_skip
    ant_geoms = [a.geom(i).name for i in range(a.ngeom) if a.geom_bodyid[i] > 0]
    for name in ant_geoms:
        np.testing.assert_array_equal(a.geom(name).size, b.geom(name).size, err_msg=name)
    assert np.all(a.actuator_gear[:, 0] == gear) and np.all(a.actuator_ctrlrange == [-1, 1])
    assert a.opt.timestep == timestep and loco.frame_skip == 5


def test_literature_ant_differs_from_gymnasiums_only_where_documented():
    """ant_hrl.xml is gymnasium's ant.xml but for the timestep, the motors' torque and the default geom's contacts."""
    from xml.etree import ElementTree

    from sb3_pilot.envs.locomotion import ANT_XML_FILES

    gymnasium_ant, hrl_ant = (ElementTree.parse(ANT_XML_FILES[name]).getroot() for name in ("gymnasium", "hrl"))
    changed = {"option": {"timestep": "0.02"}, "motor": {"gear": "30"}}
    changed["geom"] = {"solref": ".02 1", "solimp": ".8 .8 .01"}  # the default geom's only
    elements = list(zip(gymnasium_ant.iter(), hrl_ant.iter(), strict=True))
    for old, new in elements:
        assert old.tag == new.tag
        expected = dict(old.attrib)
        if old.tag in changed and (old.tag != "geom" or "density" in old.attrib):
            expected.update(changed[old.tag])
        assert new.attrib == expected, (old.tag, old.attrib.get("name") or old.attrib.get("joint"))


def test_literature_ant_rarely_flips_under_random_actions():
    """Under the same uniform random actions, gymnasium's Ant ends up on its back, the literature's does not."""
    from sb3_pilot.envs.locomotion import ant_up_z

    def lowest_up_z(env_id: str) -> float:
        env = gym.make(env_id, max_episode_steps=300)
        env.reset(seed=0)
        env.action_space.seed(0)
        up_z = []
        for _ in range(300):
            env.step(env.action_space.sample())
            up_z.append(ant_up_z(env.unwrapped.data.qpos))
        return min(up_z)

    assert lowest_up_z("Pilot/AntLocomotion-v0") < 0 < lowest_up_z("Pilot/AntLocomotion-v1")


def test_the_ant_of_a_task_is_read_from_its_model():
    import gymnasium_robotics  # noqa: F401  (registers AntMaze_UMaze-v5)

    from sb3_pilot.envs.locomotion import ANT_XML_FILES, ant_of, check_same_ant

    v0, v1 = gym.make("Pilot/AntLocomotion-v0"), gym.make("Pilot/AntMaze-v1")
    robotics = gym.make("AntMaze_UMaze-v5", xml_file=ANT_XML_FILES["hrl"])
    assert (ant_of(v0), ant_of(v1), ant_of(robotics), ant_of(gym.make("Pilot/Maze2D-v0"))) == ("gymnasium", "hrl", "hrl", None)
    check_same_ant(v1, robotics)  # the same Ant in two tasks
    check_same_ant(v0, gym.make("Pilot/Maze2D-v0"))  # no Ant to compare
    with pytest.raises(ValueError, match=r"trained on 'gymnasium'.*simulates 'hrl'"):
        check_same_ant(v0, v1, "controller.zip")


def test_ant_must_be_named():
    with pytest.raises(ValueError, match="ant must be one of"):
        gym.make("Pilot/AntLocomotion-v1", ant="hiro")
    with pytest.raises(ValueError, match="ant must be one of"):
        gym.make("Pilot/AntMaze-v0", ant="gym")
