"""The transfer pairs: their stage graphs, both similarities of the bonus, pixel-only image agents, the demo budget."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from sb3_pilot.experiments.challenges import BUDGETS, CHALLENGES, REUSE_SHIPPED, run_challenge
from sb3_pilot.experiments.challenges.definitions import HER, IMAGE_ENCODER, PILOT_DISPLACEMENT, PILOT_PAPER
from sb3_pilot.experiments.challenges.runner import count_sources
from sb3_pilot.experiments.challenges.stages import REPO_DIR
from sb3_pilot.experiments.demo import BUDGET as DEMO_BUDGET
from sb3_pilot.experiments.pairs import FINAL_EVAL, _pace, add_statistics, evaluate_final, table
from sb3_pilot.experiments.pairs import main as pairs_main
from sb3_pilot.experiments.zoo import hyperparams_dir

PAIRS = {
    "high-dim-action": ("Pilot/FetchReach-v0", "Pilot/FetchReachHighDim-v0"),
    "high-dim-action-push": ("Pilot/FetchPush-v0", "Pilot/FetchPushHighDim-v0"),
    "vec-to-image": ("Pilot/FetchReach-v0", "Pilot/FetchReachImage-v0"),
    "vec-to-image-reacher": ("Pilot/Reacher-v0", "Pilot/ReacherImage-v0"),
    "complex-morph": ("Pilot/PointLocomotion-v0", "Pilot/AntLocomotion-v0"),
    "zero-shot-ant-maze": ("Pilot/Maze2D-v0", "Pilot/AntMaze-v0"),
    "maze-car": ("Pilot/Maze2D-v0", "Pilot/Maze2DCar-v0"),  # beyond the paper: a cheap few-shot pair
    "wall-maze-car": ("Pilot/WallMaze2D-v0", "Pilot/WallMaze2DCar-v0"),  # beyond the paper: a SAC + HER teacher
}
#: Zero-shot pairs on gymnasium-robotics' own IDs, compared with the same controller unguided (no SAC + HER stage)
UNGUIDED_BASELINE = {
    "pointmaze-to-antmaze": ("PointMaze_UMaze-v3", "AntMaze_UMaze-v5"),
    "zero-shot-ant-maze-v1": ("Pilot/Maze2D-v0", "Pilot/AntMaze-v1"),  # the literature's Ant
}
BONUS = ("vec-to-image", "vec-to-image-reacher", "complex-morph", "maze-car")
PIXEL_POLICY = "sb3_pilot.common.torch_layers.PixelGoalSACPolicy"


def test_pairs() -> None:
    """The paper's six pairs and the cheap maze pairs, each with a source, PILoT and SAC+HER on the target, at every budget."""
    assert set(CHALLENGES) == set(PAIRS) | set(UNGUIDED_BASELINE)
    for name, (source_env, target_env) in UNGUIDED_BASELINE.items():
        challenge = CHALLENGES[name]
        stages = {stage.name: stage for stage in challenge.stages}
        assert challenge.target_env == target_env and challenge.stages[0].env_id == source_env, name
        assert stages["unguided"].method is not None and stages["unguided"].env_id == target_env, name
        assert stages["pilot"].method is not None and stages["pilot"].env_id == target_env, name
        assert stages["pilot"].compared_with == "unguided", name  # its verdict: against the controller unguided
    for name, (source_env, target_env) in PAIRS.items():
        challenge = CHALLENGES[name]
        assert challenge.target_env == target_env
        assert challenge.stages[0].env_id == source_env, name
        assert {"smoke", "cpu"} <= set(challenge.steps), name
        stages = {stage.name: stage for stage in challenge.stages}
        assert stages["her"].method == HER and stages["her"].env_id == target_env, name
        for budget, steps in challenge.steps.items():
            assert set(steps) <= set(stages), (name, budget)


@pytest.mark.parametrize("name", BONUS)
def test_bonus_pairs_run_both_similarities(name: str) -> None:
    """HER+PILoT twice, the paper's goal_cosine (pilot) and displacement_cosine (pilot_disp), on the same planner."""
    stages = {stage.name: stage for stage in CHALLENGES[name].stages}
    outputs = {"distill": Path("planner.pt")}
    variants = (("pilot", PILOT_PAPER, "goal_cosine"), ("pilot_disp", PILOT_DISPLACEMENT, "displacement_cosine"))
    for stage_name, method, similarity in variants:
        stage = stages[stage_name]
        assert stage.method == method and stage.conf_file == "sac_pilot.yml" and stage.needs == ("distill",)
        ((wrapper, kwargs),) = stage.params(outputs)["env_wrapper"][0].items()
        assert wrapper == "sb3_pilot.PilotBonusWrapper" and kwargs["similarity"] == similarity
        assert kwargs["planner"] == "planner.pt" and kwargs["beta"] == 1.0
    for budget in ("smoke", "cpu"):
        steps = CHALLENGES[name].steps[budget]
        assert steps["pilot"] == steps["pilot_disp"] == steps["her"], (name, budget)


@pytest.mark.parametrize("conf", ["sac.yml", "sac_pilot.yml", "cpu/sac.yml", "cpu/sac_pilot.yml"])
def test_image_entries_are_pixel_only(conf: str) -> None:
    """Both methods' image agents use the pixel-only policy (the YAML), with the encoder the challenges name."""
    entries = yaml.safe_load((hyperparams_dir() / conf).read_text())
    for env_id in ("Pilot/FetchReachImage-v0", "Pilot/ReacherImage-v0"):
        assert entries[env_id]["policy"] == PIXEL_POLICY, (conf, env_id)
    if "sac_pilot" in conf:  # the paper's targets: the paper's similarity; the maze cars (beyond it): the measured better
        for env_id, entry in entries.items():
            similarity = "displacement_cosine" if "Maze2DCar" in env_id else "goal_cosine"
            assert entry["env_wrapper"][0]["sb3_pilot.PilotBonusWrapper"]["similarity"] == similarity, env_id
    assert IMAGE_ENCODER in ("nature", "paper")
    for name in ("vec-to-image", "vec-to-image-reacher"):
        challenge = CHALLENGES[name]
        for conf in ("sac.yml", "sac_pilot.yml"):
            recipe = yaml.safe_load((hyperparams_dir() / "cpu" / challenge.recipe / conf).read_text())
            kwargs = eval(recipe[challenge.target_env]["policy_kwargs"])["features_extractor_kwargs"]
            assert kwargs == {"encoder": IMAGE_ENCODER}, (name, conf)


def test_demo_budget_is_named() -> None:
    """make demo runs the named ``demo`` budget of High-Dim-Action (test_challenges.py runs it at smoke size)."""
    assert DEMO_BUDGET == "demo" and DEMO_BUDGET in BUDGETS
    steps = CHALLENGES["high-dim-action"].steps["demo"]
    assert steps["source"] >= 8000 and steps["pilot"] == steps["her"] <= steps["source"]


def test_maze_car_shipped_planner_is_shared() -> None:
    """``maze-car --reuse-shipped``: one shipped Maze2D planner for every seed, the target stages exactly maze-car's."""
    from sb3_pilot.distill import GoalPlanner

    shipped, full = REUSE_SHIPPED["maze-car"], CHALLENGES["maze-car"]
    assert shipped.stages[0].name == "distill" and shipped.stages[1:] == full.stages[2:]
    assert shipped.recipe == full.recipe and shipped.target_env == full.target_env
    assert shipped.steps["cpu"] == {stage.name: full.steps["cpu"][stage.name] for stage in shipped.stages[1:]}
    assert GoalPlanner.load(shipped.stages[0].path).source_task == "Pilot/Maze2D-v0"


def test_pace_reads_censored_ratios_as_bounds() -> None:
    """A side whose seeds did not all reach 90% is counted at the budget's end: the ratio is then a bound."""
    ratio = {"value": 0.8, "ci": [0.7, 0.95]}

    def stats(reached: int) -> dict:
        return {"seeds": 10, "steps_to_90": {"reached": reached}}

    assert _pace(ratio, stats(10), stats(10)) == "0.80 [0.70, 0.95]"
    assert _pace(ratio, stats(10), stats(2)) == "at most 0.80 [0.70, 0.95]"  # SAC+HER's steps understated
    assert _pace(ratio, stats(0), stats(10)) == "at least 0.80 [0.70, 0.95]"
    assert _pace(ratio, stats(7), stats(2)).endswith("(censored seeds on both sides)")
    assert _pace(None, stats(0), stats(0)) == "-"


def test_pairs_cli_bad_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for argv in (["--reps", "0"], ["--episodes", "0"]):
        with pytest.raises(SystemExit):
            pairs_main(argv)
        assert "must be at least 1" in capsys.readouterr().err
    for argv, missing in (([str(tmp_path)], f"any challenge folder of {tmp_path}"), ([str(tmp_path), "maze-car"], "maze-car")):
        with pytest.raises(SystemExit):
            pairs_main(argv)
        assert f"no summary.json in {missing}" in capsys.readouterr().err.replace(f"{tmp_path}/maze-car", "maze-car")


def test_count_sources() -> None:
    """Distinct sources of a stage's seeds: the stages without inputs it reads from, told apart by their hashes."""
    challenge = CHALLENGES["zero-shot-ant-maze"]  # pilot reads distill (which reads maze) and controller
    seeds = [0, 1, 2]
    own = {f"seed_{seed}/{name}": {"config_hash": f"{name}{seed}"} for seed in seeds for name in ("maze", "controller")}
    assert count_sources(challenge, "pilot", own, seeds) == 3
    one_maze = {**own, **{f"seed_{seed}/maze": {"config_hash": "maze"} for seed in seeds}}
    assert count_sources(challenge, "pilot", one_maze, seeds) == 3  # each seed's controller still its own
    shipped = {**one_maze, **{f"seed_{seed}/controller": {"config_hash": "controller"} for seed in seeds}}
    assert count_sources(challenge, "pilot", shipped, seeds) == 1
    assert count_sources(challenge, "her", own, seeds) == 0  # from scratch
    assert count_sources(challenge, "pilot", own, [0, 1, 2, 3]) is None  # seed 3's sources not recorded
    assert count_sources(challenge, "no_such_stage", own, seeds) is None


@pytest.mark.parametrize(("folder", "shared"), [("maze-car-shipped", True), ("complex-morph", False)])
def test_committed_summaries_load_with_their_sources(tmp_path: Path, folder: str, shared: bool) -> None:
    """A summary.json written before the runner recorded sources: pairs finds them from its stages' hashes (one shipped
    planner for every seed, or a source trained per seed), and the verdict counts its seeds."""
    run_dir = tmp_path / folder
    run_dir.mkdir()
    shutil.copy(REPO_DIR / "zoo_runs" / folder / "summary.json", run_dir / "summary.json")
    summary = add_statistics(run_dir, reps=20)
    assert json.loads((run_dir / "summary.json").read_text()) == summary
    for method, result in summary["methods"].items():
        seeds = len(result["runs"])
        expected = 0 if result["stage"] in ("her", "mega") else 1 if shared else seeds
        stats = summary["statistics"]["methods"][method]
        assert result["sources"] == stats["sources"] == expected, method
        assert stats["seeds"] == seeds and stats["aggregate"] == ("IQM" if seeds >= 4 else "mean")
        comparison = summary["statistics"]["comparisons"].get(method)
        if comparison is not None and seeds < 5:
            assert not comparison["verdict"].startswith(("confirmed", "worse")), comparison["verdict"]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["high-dim-action-push", "vec-to-image-reacher"])
def test_new_pairs_smoke(tmp_path: Path, name: str) -> None:
    """The pairs the runner lacked, end to end at the smoke budget, and their row of the results table."""
    summary = run_challenge(name, "smoke", root=tmp_path)
    run_dir = tmp_path / name
    methods = {stage.method for stage in CHALLENGES[name].stages if stage.method is not None}
    assert set(summary["methods"]) == methods
    for result in summary["methods"].values():
        assert result["env_id"] == PAIRS[name][1] and result["mean"]["timesteps"][-1] > 0
    if name == "vec-to-image-reacher":
        args = (run_dir / "models/seed_0/her/sac/Pilot-ReacherImage-v0_1/Pilot-ReacherImage-v0/config.yml").read_text()
        assert PIXEL_POLICY in args and f"encoder: {IMAGE_ENCODER}" in args
    rows = table([run_dir], episodes=1, reps=200)
    assert rows.count("\n") == 1 + len(methods)
    final = json.loads((run_dir / FINAL_EVAL).read_text())
    assert set(final) == methods and all(entry["seed_0"]["distance"] >= 0 for entry in final.values())


def test_final_eval_reads_a_rerun_stage_not_its_stale_record(tmp_path: Path) -> None:
    """A stage run again after final_eval.json recorded it: its new evaluations.npz wins over the old record."""
    challenge = REUSE_SHIPPED["maze-car"]
    run_dir = tmp_path / challenge.name
    run_dir.mkdir()
    (run_dir / "summary.json").write_text(json.dumps({"challenge": challenge.name, "budget": "cpu", "seeds": [0]}))
    stage = next(stage for stage in challenge.stages if stage.name == "her")
    model = stage.output(run_dir / "models/seed_0/her")
    model.parent.mkdir(parents=True)
    model.touch()
    np.savez(model.parent / "evaluations.npz", successes=np.array([[0.0, 1.0]]), final_distances=np.array([0.25]))
    stale = {stage.method: {"seed_0": {"success": 0.0, "distance": 9.0, "episodes": 10}}}
    (run_dir / FINAL_EVAL).write_text(json.dumps(stale))
    results = evaluate_final(run_dir)
    assert results[stage.method]["seed_0"] == {"success": 0.5, "distance": 0.25, "episodes": 2}
    assert json.loads((run_dir / FINAL_EVAL).read_text()) == results
