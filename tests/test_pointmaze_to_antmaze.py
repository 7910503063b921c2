"""
The ``pointmaze-to-antmaze`` challenge on gymnasium-robotics' own IDs: the open-ground controller's recipe as a
wrapper (:class:`AntControllerRecipe`) and inputs on ``AntMaze_Open-v5``, the far start and goal of the U-maze, the
controller's evaluation stage, and the challenge at the smoke budget.
"""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import gymnasium_robotics
import numpy as np
import pytest
import torch as th

from sb3_pilot.common.torch_layers import GoalRelativeExtractor
from sb3_pilot.envs.controller_recipe import AntControllerRecipe
from sb3_pilot.envs.maze import UMAZE_GOAL_CELL, UMAZE_START_CELL, umaze_cell_to_xy
from sb3_pilot.experiments.challenges.controller import far_umaze_map, reported_success

gym.register_envs(gymnasium_robotics)
#: cpu/ant_controller_upright.yml's options of Pilot/AntLocomotion-v0 (the recipe)
RECIPE = {
    "goal_range": (0.5, 3.0),
    "goal_hold_steps": 25,
    "distance_threshold": 0.5,
    "reward_type": "dense",
    "upright_reward": 1.0,
    "goal_reward": 1.0,
    "ctrl_cost_weight": 0.25,
    "terminate_when_flipped": True,
    "flip_up_z": 0.5,
}
OPEN = {"include_cfrc_ext_in_observation": False}


def test_wrapper_rewards_as_the_recipe_task() -> None:
    """On the plain Ant task, the wrapper gives the reward and the end of Pilot/AntLocomotion-v0 with the recipe's
    options, for the same goal and actions."""
    recipe = gym.make("Pilot/AntLocomotion-v0", **RECIPE)
    wrapped = AntControllerRecipe(gym.make("Pilot/AntLocomotion-v0", ctrl_cost_weight=0.25))
    recipe.reset(seed=1)
    wrapped.reset(seed=1)
    wrapped.goal = recipe.unwrapped.goal.copy()
    rng = np.random.default_rng(0)
    for step in range(200):
        action = rng.uniform(-1, 1, size=8).astype(np.float32)
        expected, got = recipe.step(action), wrapped.step(action)
        assert got[1] == pytest.approx(expected[1], abs=1e-9), step
        assert got[2] == expected[2] and got[4]["flipped"] == expected[4]["flipped"]
        np.testing.assert_allclose(got[0]["desired_goal"], expected[0]["desired_goal"])
        if expected[2]:
            break
    assert expected[2], "the random Ant should flip (the end of the episode is compared)"


def test_goals_a_short_walk_away_in_the_arena() -> None:
    env = AntControllerRecipe(gym.make("AntMaze_Open-v5", **OPEN))
    maze = env.unwrapped.maze
    for seed in range(20):
        obs, info = env.reset(seed=seed)
        distance = np.linalg.norm(obs["desired_goal"] - obs["achieved_goal"])
        assert 0.5 <= distance <= 3.0 and not info["is_success"]
        assert obs["observation"].shape == (27,) and obs["desired_goal"].dtype == np.float64
        for dx in (-1.0, 1.0):  # at least wall_margin from every wall cell
            row, col = maze.cell_xy_to_rowcol(obs["desired_goal"] + dx)
            assert maze.maze_map[row][col] != 1
    assert env.compute_reward(obs["achieved_goal"], obs["achieved_goal"] + np.array([0.4, 0.0]), {}) == 0.0
    assert env.compute_reward(obs["achieved_goal"], obs["achieved_goal"] + np.array([0.4, 0.4]), {}) == -1.0


def test_a_held_goal_moves_on() -> None:
    env = AntControllerRecipe(gym.make("AntMaze_Open-v5", **OPEN), goal_hold_steps=2)
    obs, _ = env.reset(seed=0)
    env.goal = obs["achieved_goal"].copy()  # reached where it stands
    zero = np.zeros(8, dtype=np.float32)
    goals = []
    for _ in range(3):
        obs, reward, _, _, info = env.step(zero)
        goals.append(obs["desired_goal"].copy())
        assert reward >= 1.0  # upright and at the goal (standing still: no progress)
    assert info["goals_reached"] == 1 and info["is_success"]
    np.testing.assert_array_equal(goals[0], goals[1])
    assert np.linalg.norm(goals[2] - obs["achieved_goal"]) >= 0.5  # a new goal from the third step on


def test_standard_layout_gives_the_recipe_inputs() -> None:
    """GoalRelativeExtractor on gymnasium-robotics' layout (no xy in observation) with (0, 1, 13) gives the features of
    the Pilot/ layout (xy first) with its defaults, for the same Ant state."""
    env = gym.make("AntMaze_Open-v5", **OPEN)
    obs, _ = env.reset(seed=0)
    for _ in range(5):
        obs, *_ = env.step(env.action_space.sample())
    standard = {key: th.as_tensor(value[None]) for key, value in obs.items()}
    pilot = {**standard, "observation": th.cat([standard["achieved_goal"], standard["observation"]], dim=1)}
    space = gym.spaces.Dict({key: gym.spaces.Box(-np.inf, np.inf, value.shape[1:]) for key, value in standard.items()})
    pilot_space = gym.spaces.Dict({**space.spaces, "observation": gym.spaces.Box(-np.inf, np.inf, (29,))})
    ours = GoalRelativeExtractor(space, position_dim=0, quaternion_index=1, velocity_index=13)
    np.testing.assert_allclose(ours(standard).numpy(), GoalRelativeExtractor(pilot_space)(pilot).numpy(), atol=1e-6)


def test_far_start_and_goal_in_both_mazes() -> None:
    """The far cells of the U in PointMaze_UMaze-v3 and AntMaze_UMaze-v5: the same places, at scales 1 and 4."""
    far = {"maze_map": far_umaze_map(), "continuing_task": False}
    ant = gym.make("AntMaze_UMaze-v5", **far, **OPEN)
    point = gym.make("PointMaze_UMaze-v3", **far)
    start, goal = umaze_cell_to_xy(UMAZE_START_CELL), umaze_cell_to_xy(UMAZE_GOAL_CELL)
    for seed in range(5):
        obs, info = ant.reset(seed=seed)
        assert np.abs(obs["achieved_goal"] - start).max() <= 1.0 and np.abs(obs["desired_goal"] - goal).max() <= 1.0
        assert reported_success(info) == 0.0
        obs, _ = point.reset(seed=seed)
        assert np.abs(4 * obs["achieved_goal"] - start).max() <= 1.0 and np.abs(4 * obs["desired_goal"] - goal).max() <= 1.0
    with pytest.raises(KeyError, match="no 'is_success' nor 'success'"):
        reported_success({})


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="MuJoCo Ant"):
        AntControllerRecipe(gym.make("Pilot/Maze2D-v0"))
    with pytest.raises(ValueError, match="goal_range"):
        AntControllerRecipe(gym.make("AntMaze_Open-v5"), goal_range=(2.0, 1.0))
    with pytest.raises(ValueError, match="goal_hold_steps"):
        AntControllerRecipe(gym.make("AntMaze_Open-v5"), goal_hold_steps=-1)


@pytest.mark.slow
def test_pointmaze_to_antmaze_smoke(tmp_path: Path) -> None:
    """SAC + HER on PointMaze -> planner -> GoalMap(4.0) guidance of the AntMaze_Open-v5 controller on
    AntMaze_UMaze-v5, beside the controller unguided and on open ground (tiny budget)."""
    from sb3_pilot import GoalPlanner
    from sb3_pilot.experiments.challenges import run_challenge

    summary = run_challenge("pointmaze-to-antmaze", "smoke", root=tmp_path)
    assert set(summary["methods"]) == {"PILoT zero-shot (0 U-maze steps)", "the controller unguided (0 U-maze steps)"}
    assert summary["methods"]["PILoT zero-shot (0 U-maze steps)"]["baseline"] == "the controller unguided (0 U-maze steps)"
    models = tmp_path / "pointmaze-to-antmaze" / "models" / "seed_0"
    planner = GoalPlanner.load(models / "distill" / "planner.pt")
    assert planner.source_task == "PointMaze_UMaze-v3" and planner.metadata["teacher_algorithm"] == "SAC"
    controller = " ".join(summary["stages"]["seed_0/controller"]["config"]["zoo"])
    assert "AntMaze_Open-v5" in controller and "cpu/antmaze_open_controller.yml" in controller
    guided = json.loads((models / "pilot" / "guidance.json").read_text())
    start = umaze_cell_to_xy(UMAZE_START_CELL)
    for episode in guided["episodes"]:
        achieved, landmarks = np.array(episode["achieved_goals"]), np.array(episode["landmarks"])
        assert np.abs(achieved[0] - start).max() <= 1.0  # the far start, in AntMaze's coordinates
        assert np.linalg.norm(landmarks - achieved, axis=1).max() < 4.0  # landmarks planned near the Ant, scaled
    unguided = json.loads((models / "unguided" / "guidance.json").read_text())
    assert len(unguided["successes"]) == 2 and "landmarks" not in unguided["episodes"][0]
    assert len(json.loads((models / "open_ground" / "guidance.json").read_text())["successes"]) == 2


def _ant_tasks(challenge_name: str, variant: str | None) -> dict[str, str | None]:
    """The Ant (``ant_of``) of every task a challenge's stages build: the controller's training task (its zoo
    ``--env-kwargs``, else its YAML entry's) and each evaluation's."""
    import yaml

    from sb3_pilot.envs.locomotion import ant_of
    from sb3_pilot.experiments.challenges import CHALLENGES, ControllerEvaluation, ZooTrain, challenge_variant
    from sb3_pilot.experiments.zoo import hyperparams_dir

    challenge = CHALLENGES[challenge_name] if variant is None else challenge_variant(challenge_name, variant)
    ants = {}
    for stage in challenge.stages:
        if isinstance(stage, ZooTrain) and stage.env_id.startswith("AntMaze"):
            entry = yaml.safe_load((hyperparams_dir() / "cpu" / stage.conf_file).read_text())[stage.env_id]
            env = gym.make(stage.env_id, **(stage.env_kwargs or entry["env_kwargs"]))
        elif isinstance(stage, ControllerEvaluation):
            env = gym.make(stage.env_id, **stage.env_kwargs)
        else:
            continue
        ants[stage.name] = ant_of(env)
        env.close()
    return ants


def test_hrl_variant_is_the_literatures_ant_in_every_task() -> None:
    """``pointmaze-to-antmaze --variant hrl`` trains and evaluates the literature's Ant in gymnasium-robotics' own
    tasks (their ``xml_file``); the challenge itself keeps gymnasium's; the teacher and its planner are the same."""
    from sb3_pilot.experiments.challenges import CHALLENGES, challenge_variant

    names = ["controller", "pilot", "unguided", "open_ground"]
    assert _ant_tasks("pointmaze-to-antmaze", "hrl") == dict.fromkeys(["pilot_switch", *names], "hrl")
    assert _ant_tasks("pointmaze-to-antmaze", None) == dict.fromkeys(names, "gymnasium")
    variant, challenge = challenge_variant("pointmaze-to-antmaze", "hrl"), CHALLENGES["pointmaze-to-antmaze"]
    assert variant.name == "pointmaze-to-antmaze-hrl" and variant.target_env == challenge.target_env
    assert variant.stages[:2] == challenge.stages[:2]  # teacher, distill
    pilot = next(stage for stage in variant.stages if stage.name == "pilot")
    assert (pilot.lead, pilot.max_horizon, pilot.goal_scale, pilot.choose_switch) == (2.75, 100, 4.0, False)
    switch = next(stage for stage in variant.stages if stage.name == "pilot_switch")
    assert switch.choose_switch and switch.compared_with == "unguided" and switch.env_kwargs == pilot.env_kwargs
    from sb3_pilot.experiments.challenges import ControllerEvaluation

    with pytest.raises(ValueError, match="choose_switch chooses the switch distance from a lead"):
        ControllerEvaluation("x", "chosen", "AntMaze_UMaze-v5", None, planner="distill", choose_switch=True)


def test_medium_variant_shares_the_hrl_controllers(tmp_path: Path) -> None:
    """``--variant hrl-medium``: the teacher on PointMaze_Medium-v3, the literature's Ant guided on AntMaze_Medium-v5's
    own cells as the guide command guides (k and the switch chosen together); its controller stages hash as the hrl
    variant's, so the hrl variant's finished controllers serve it."""
    from sb3_pilot.experiments.challenges import challenge_variant
    from sb3_pilot.experiments.challenges.definitions import BUDGETS
    from sb3_pilot.experiments.challenges.runner import context_kwargs, stage_tasks

    hrl, medium = (challenge_variant("pointmaze-to-antmaze", name) for name in ("hrl", "hrl-medium"))
    assert _ant_tasks("pointmaze-to-antmaze", "hrl-medium") == dict.fromkeys(
        ["controller", "pilot", "unguided", "open_ground"], "hrl"
    )
    teacher, distill = medium.stages[:2]
    assert (teacher.env_id, medium.target_env) == ("PointMaze_Medium-v3", "AntMaze_Medium-v5")
    # the Medium teacher's rollouts: a goal that moves on once reached; the U-maze's as they were
    assert distill.env_kwargs == {"reset_target": True} and hrl.stages[1].env_kwargs == {}
    pilot = next(stage for stage in medium.stages if stage.name == "pilot")
    assert pilot.choose_switch and (pilot.lead, pilot.max_horizon, pilot.goal_scale) == (2.75, 100, 4.0)
    assert "maze_map" not in pilot.env_kwargs and pilot.env_kwargs["continuing_task"] is False
    hashes = [
        {
            key: task.digest
            for key, task in stage_tasks(c, [0, 1], tmp_path / c.name, context_kwargs(c, BUDGETS["cpu"])).items()
        }
        for c in (hrl, medium)
    ]
    for key in ("seed_0/controller", "seed_1/chosen", "seed_1/open_ground"):
        assert hashes[0][key] == hashes[1][key]
    assert hashes[0]["seed_0/teacher"] != hashes[1]["seed_0/teacher"]


def test_unknown_variant_refused_with_the_list(capsys: pytest.CaptureFixture[str]) -> None:
    from sb3_pilot.experiments.challenges.__main__ import main

    with pytest.raises(SystemExit):
        main(["pointmaze-to-antmaze", "--variant", "d4rl", "--dry-run"])
    assert (
        "no variant 'd4rl'; the variants: pointmaze-to-antmaze --variant hrl, pointmaze-to-antmaze --variant hrl-medium"
        in capsys.readouterr().err
    )
    with pytest.raises(SystemExit):
        main(["maze-car", "--variant", "hrl", "--dry-run"])
    assert "maze-car has no variant 'hrl'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["pointmaze-to-antmaze", "--variant", "hrl", "--reuse-shipped", "--dry-run"])
    assert "not with 'all' nor --reuse-shipped" in capsys.readouterr().err


def test_gymnasiums_ant_controller_refused_on_the_literatures_umaze(tmp_path: Path) -> None:
    """A controller whose zoo settings say it trained on AntMaze_Open-v5 with gymnasium's Ant is refused, by name, on
    AntMaze_UMaze-v5 with the literature's (and the reverse); its own Ant is accepted."""
    import yaml

    from sb3_pilot.envs.locomotion import ANT_XML_FILES
    from sb3_pilot.experiments.challenges.controller import check_controller_ant

    for trained, guided in (("gymnasium", "hrl"), ("hrl", "gymnasium")):
        model = tmp_path / trained / "AntMaze_Open-v5.zip"
        (model.parent / model.stem).mkdir(parents=True)
        env_kwargs = {**OPEN, **({"xml_file": ANT_XML_FILES["hrl"]} if trained == "hrl" else {})}
        (model.parent / model.stem / "args.yml").write_text(
            yaml.safe_dump({"env": "AntMaze_Open-v5", "env_kwargs": env_kwargs})
        )
        maze = gym.make("AntMaze_UMaze-v5", **OPEN, **({"xml_file": ANT_XML_FILES["hrl"]} if guided == "hrl" else {}))
        with pytest.raises(ValueError, match=f"trained on '{trained}'.*simulates '{guided}'"):
            check_controller_ant(model, maze)
        own = gym.make("AntMaze_UMaze-v5", **env_kwargs)
        check_controller_ant(model, own)
        maze.close(), own.close()


def test_the_controllers_task_options_travel_with_it(tmp_path: Path) -> None:
    """What a controller sees and which Ant it moves come from its zoo run (a machine path of the package's Ant file
    found here); a guided task asking for others is refused by name, and observations that differ are named."""
    import yaml

    from sb3_pilot.envs.locomotion import ANT_XML_FILES
    from sb3_pilot.experiments.challenges.controller import check_controller_inputs
    from sb3_pilot.experiments.zoo_run import carried_env_kwargs, with_carried_env_kwargs

    model = tmp_path / "AntMaze_Open-v5.zip"
    (model.parent / model.stem).mkdir()
    elsewhere = "/another/machine/sb3_pilot/envs/assets/ant_hrl.xml"
    trained = {"max_episode_steps": 500, "include_cfrc_ext_in_observation": False, "xml_file": elsewhere}
    (model.parent / model.stem / "args.yml").write_text(yaml.safe_dump({"env": "AntMaze_Open-v5", "env_kwargs": trained}))
    carried = {"include_cfrc_ext_in_observation": False, "xml_file": ANT_XML_FILES["hrl"]}
    assert carried_env_kwargs(model) == carried
    assert with_carried_env_kwargs(model, "AntMaze_Medium-v5", {"continuing_task": False}) == {
        **carried,
        "continuing_task": False,
    }
    with pytest.raises(ValueError, match=r"include_cfrc_ext_in_observation=True \(trained with False\)"):
        with_carried_env_kwargs(model, "AntMaze_Medium-v5", {"include_cfrc_ext_in_observation": True})
    assert carried_env_kwargs(tmp_path / "no_settings.zip") == {}
    assert with_carried_env_kwargs(model, "Pilot/AntMaze-v1", {}) == {}  # names its Ant by version: nothing carried

    controller_space = gym.make("AntMaze_Open-v5", **carried).observation_space
    with_forces = gym.make("AntMaze_Medium-v5", xml_file=ANT_XML_FILES["hrl"])
    with pytest.raises(ValueError, match=r"observation: \(27,\) trained, \(105,\) here.*include_cfrc_ext_in_observation"):
        check_controller_inputs(model, controller_space, with_forces)
    check_controller_inputs(
        model, controller_space, gym.make("AntMaze_Medium-v5", **with_carried_env_kwargs(model, "AntMaze_Medium-v5", {}))
    )
