"""The four transfer challenges end to end at the ``smoke`` budget, resuming, summary.json, plots and the demo."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from sb3_pilot.experiments.challenges import CHALLENGES, format_table, only_stages, run_challenge, steps_to
from sb3_pilot.experiments.challenges.__main__ import main as challenges_main
from sb3_pilot.experiments.challenges.definitions import BUDGETS
from sb3_pilot.experiments.challenges.stages import STAGE_COMMAND, STAGE_LOG, STAGE_MARKER
from sb3_pilot.experiments.demo import BONUS_BUDGET, BUDGET
from sb3_pilot.experiments.demo import main as demo_main
from sb3_pilot.experiments.plots import main as plots_main
from sb3_pilot.transfer.state_planner import load_vec_normalize


def check_summary(summary: dict[str, Any], name: str, run_dir: Path) -> None:
    """The schema of summary.json, and that it is what run_challenge returned."""
    assert json.loads((run_dir / "summary.json").read_text()) == summary
    challenge = CHALLENGES[name]
    assert summary["challenge"] == name and summary["budget"] == "smoke" and summary["seeds"] == [0]
    assert summary["target_env"] == challenge.target_env and summary["thresholds"] == [0.5, 0.9]
    assert set(summary["methods"]) == {stage.method for stage in challenge.stages if stage.method is not None}
    for result in summary["methods"].values():
        assert result["env_id"] == challenge.target_env
        for curve in (*result["runs"], result["mean"]):
            assert len(curve["timesteps"]) == len(curve["success_rate"]) >= 1
            assert all(0.0 <= rate <= 1.0 for rate in curve["success_rate"])
            assert {"steps_to_50", "steps_to_90"} <= set(curve)
            # every method is also measured by distance: each goal task's evaluations record its final distance
            assert len(curve["final_distance"]) == len(curve["timesteps"])
            assert all(0.0 <= distance < 100.0 for distance in curve["final_distance"])
        assert [run["seed"] for run in result["runs"]] == [0]
    assert set(summary["stages"]) == {f"seed_0/{stage.name}" for stage in challenge.stages}
    for stage in summary["stages"].values():
        assert len(stage["config_hash"]) == 16 and stage["wall_time_s"] >= 0
    assert summary["wall_time_s"] > 0
    # models and the zoo's logs stay under models/ (gitignored), results next to it
    assert not list(run_dir.glob("*.zip")) and list((run_dir / "models").rglob("*.zip"))


def check_pngs(run_dir: Path, expected: set[str]) -> None:
    plots_main([str(run_dir)])
    for name in expected:
        assert (run_dir / name).stat().st_size > 10_000, name


def test_steps_to() -> None:
    assert steps_to([100, 200, 300], [0.2, 0.6, 0.95]) == {"steps_to_50": 200, "steps_to_90": 300}
    assert steps_to([100, 200], [0.0, 0.5]) == {"steps_to_50": 200, "steps_to_90": None}


def test_a_comparison_names_a_method_of_the_challenge() -> None:
    """A controller evaluation compared with a stage that is no compared method of its challenge: refused at once."""
    wall = CHALLENGES["wall-maze-car"]
    stages = tuple(
        dataclasses.replace(stage, compared_with="controller") if stage.name == "guided" else stage for stage in wall.stages
    )
    with pytest.raises(ValueError, match="'guided' of wall-maze-car is compared with 'controller'"):
        dataclasses.replace(wall, stages=stages)


def test_only_stages_keeps_what_a_method_is_compared_with() -> None:
    """Asking for a guided controller brings the unguided one it is compared with, and what both read from."""
    kept = [stage.name for stage in only_stages(CHALLENGES["wall-maze-car"], ["guided"]).stages]
    assert kept == ["teacher", "distill", "controller", "guided", "unguided"]
    kept = [stage.name for stage in only_stages(CHALLENGES["zero-shot-ant-maze"], ["pilot"]).stages]
    assert kept == ["maze", "distill", "controller", "chosen", "pilot", "unguided"]


def test_unknown_challenge(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="Unknown challenge"):
        run_challenge("nope", root=tmp_path)
    with pytest.raises(SystemExit):
        challenges_main(["nope"])


def test_a_recipe_missing_at_a_budget_is_named_before_any_work(tmp_path: Path) -> None:
    # zero-shot-ant-maze's controller recipe is written for the cpu budget only: at paper its YAML is not there
    with pytest.raises(ValueError, match=r"hyperparams/ant_controller_upright\.yml at the paper budget: no such file .*cpu/"):
        run_challenge("zero-shot-ant-maze", budget="paper", seeds=[0], root=tmp_path, dry_run=True)
    assert not (tmp_path / "zero-shot-ant-maze").exists()


def test_high_dim_action_smoke_resume_and_plots(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """UDPO source -> transferred planner vs SAC+HER, through the zoo; a rerun skips every stage."""
    challenges_main(["high-dim-action", "--budget", "smoke", "--root", str(tmp_path), "--no-progress"])
    run_dir = tmp_path / "high-dim-action"
    summary = json.loads((run_dir / "summary.json").read_text())
    check_summary(summary, "high-dim-action", run_dir)
    pilot = summary["stages"]["seed_0/pilot"]["config"]["zoo"]
    assert "sb3_pilot.transfer.StatePlannerTransferCallback" in pilot[-1] and "--conf-file" in pilot
    for stage in ("source", "pilot", "her"):  # RL-Zoo's VecNormalize on every stage (the recipe's), the baseline's included
        config = summary["stages"][f"seed_0/{stage}"]["config"]
        assert config["preset"]["normalize"] is True and "cpu/fetch/" in " ".join(config["zoo"]), stage
    # the target's saved statistics are the source's, frozen with the transferred planner
    saved = {
        stage: load_vec_normalize(next((run_dir / "models" / "seed_0" / stage).rglob("vecnormalize.pkl")))
        for stage in ("source", "pilot")
    }
    assert not saved["pilot"].training
    for key, stats in saved["source"].obs_rms.items():
        np.testing.assert_array_equal(saved["pilot"].obs_rms[key].mean, stats.mean, err_msg=key)
        np.testing.assert_array_equal(saved["pilot"].obs_rms[key].var, stats.var, err_msg=key)
    for stage in ("source", "pilot", "her"):  # each stage ran in a process of its own, its output and command beside it
        stage_dir = run_dir / "models" / "seed_0" / stage
        assert "python -m sb3_pilot.experiments.zoo train" in (stage_dir / STAGE_LOG).read_text()
        command = (stage_dir / STAGE_COMMAND).read_text()
        assert command.startswith("python -m sb3_pilot.experiments.zoo train --algo") and " -params " in command
    out = capsys.readouterr().out  # the terminal gets short lines: what each stage does, not its command
    assert "seed 0 source: udpo on Pilot/FetchReach-v0, 400 env steps" in out and "-params" not in out
    marker = run_dir / "models" / "seed_0" / "source" / STAGE_MARKER
    marker_time = marker.stat().st_mtime

    again = run_challenge("high-dim-action", "smoke", root=tmp_path)
    out = capsys.readouterr().out
    assert out.count("skipped") == 3 and marker.stat().st_mtime == marker_time
    assert again["methods"] == summary["methods"]

    # another step count for the baseline only: the baseline reruns, the other stages do not
    rerun = run_challenge("high-dim-action", "smoke", root=tmp_path, steps={"her": 200})
    out = capsys.readouterr().out
    assert out.count("skipped") == 2 and "seed 0 her: finished" in out
    assert rerun["methods"]["SAC+HER (scratch)"]["runs"][0]["timesteps"][-1] == 200

    # an interrupted stage (no marker) is redone from scratch
    (run_dir / "models" / "seed_0" / "her" / STAGE_MARKER).unlink()
    run_challenge("high-dim-action", "smoke", root=tmp_path, steps={"her": 200})
    assert "seed 0 her: finished" in capsys.readouterr().out
    check_pngs(run_dir, {"success.png", "plan_error.png"})


def test_zero_shot_ant_maze_smoke(tmp_path: Path) -> None:
    """Maze2D UDPO -> distilled planner guiding an Ant-Locomotion controller on Ant-Maze (0 steps) vs SAC+HER."""
    summary = run_challenge("zero-shot-ant-maze", "smoke", root=tmp_path)
    run_dir = tmp_path / "zero-shot-ant-maze"
    check_summary(summary, "zero-shot-ant-maze", run_dir)
    zero_shot = summary["methods"]["PILoT zero-shot (0 Ant-Maze steps)"]
    assert zero_shot["mean"]["timesteps"] == [0] and zero_shot["guidance"]["horizon"] == 3
    assert zero_shot["baseline"] == "the controller unguided (0 Ant-Maze steps)"  # compared with the same controller
    unguided = json.loads((run_dir / "models" / "seed_0" / "unguided" / "guidance.json").read_text())
    assert unguided["planner"] is None and len(unguided["successes"]) == 2  # the smoke budget's episodes
    guidance = json.loads((run_dir / "models" / "seed_0" / "pilot" / "guidance.json").read_text())
    episode = guidance["episodes"][0]
    assert len(episode["achieved_goals"]) == len(episode["landmarks"]) == 501  # reset + 500 steps
    # the guided controller is the checkpoint chosen on open ground among the zoo's 7 and the final model
    choice = json.loads((run_dir / "models" / "seed_0" / "chosen" / "choice.json").read_text())
    assert [score["steps"] for score in choice["checkpoints"]] == [70, 140, 210, 280, 350, 420, 490, 500]
    assert summary["stages"]["seed_0/pilot"]["config"]["controller"] == "<run>/models/seed_0/chosen/controller.zip"
    holdout = json.loads((run_dir / "models" / "seed_0" / "distill" / "distill.json").read_text())
    assert holdout["nll"] < holdout["nll_untrained"]
    # the maze source trains on uniform starts and goals (the zoo's --env-kwargs), as its args.yml records
    args = (run_dir / "models/seed_0/maze/udpo/Pilot-Maze2D-v0_1/Pilot-Maze2D-v0/args.yml").read_text()
    assert "goal_distribution: uniform" in args
    check_pngs(run_dir, {"success.png", "plan_error.png", "landmarks.png"})


@pytest.mark.slow
@pytest.mark.parametrize("name", ["vec-to-image", "complex-morph"])
def test_bonus_challenges_smoke(tmp_path: Path, name: str) -> None:
    """UDPO source -> distilled planner -> HER + PILoT bonus vs SAC+HER (image rendering, the Ant: slow)."""
    summary = run_challenge(name, "smoke", root=tmp_path)
    run_dir = tmp_path / name
    check_summary(summary, name, run_dir)
    pilot = summary["stages"]["seed_0/pilot"]["config"]["zoo"]
    assert "sb3_pilot.PilotBonusWrapper" in " ".join(pilot) and "sac_pilot.yml" in " ".join(pilot)
    check_pngs(run_dir, {"success.png", "plan_error.png"})


def test_maze_car_smoke(tmp_path: Path) -> None:
    """Maze2D UDPO -> distilled planner -> HER + bonus on the car, and MEGA (cheap: pure numpy), statistics and rows."""
    from sb3_pilot.experiments.pairs import table

    summary = run_challenge("maze-car", "smoke", root=tmp_path)
    run_dir = tmp_path / "maze-car"
    check_summary(summary, "maze-car", run_dir)
    zoo = summary["stages"]["seed_0/pilot_disp"]["config"]["zoo"]
    assert "displacement_cosine" in " ".join(zoo) and "Pilot/Maze2DCar-v0" in zoo
    # the YAML's MEGA callback survives the stage's own (the CSV logger): a MEGA wrapper without it changes nothing
    assert "sb3_pilot.baselines.MegaCallback" in " ".join(summary["stages"]["seed_0/mega"]["config"]["zoo"])
    rows = table([run_dir], reps=200)
    assert rows.count("\n") == 1 + 4 and "too few seeds (1)" in rows  # one seed: intervals, but no verdict
    assert "IQM ratio to SAC+HER's" in rows and all(row.count("|") == 13 for row in rows.splitlines())
    assert "| HER+PILoT (bonus, displacement_cosine) | 1 (1 source) | 300 | mean " in rows  # its own source; the mean
    assert "| SAC+HER (scratch) | 1 | 300 | mean " in rows
    statistics = json.loads((run_dir / "summary.json").read_text())["statistics"]
    assert set(statistics["comparisons"]) == {
        "HER+PILoT (bonus, paper: goal_cosine)",
        "HER+PILoT (bonus, displacement_cosine)",
        "SAC+HER+MEGA (baseline)",
    }
    check_pngs(run_dir, {"success.png", "plan_error.png", "landmarks.png"})


def test_three_seeds_get_statistics(tmp_path: Path) -> None:
    """From 3 seeds on, ``summary.json`` carries the rliable statistics and the printed table their verdicts."""
    challenge = only_stages(CHALLENGES["maze-car"], ["her", "mega"])
    summary = run_challenge(challenge, "smoke", seeds=[0, 1, 2], root=tmp_path, jobs=2)
    statistics = json.loads((tmp_path / "maze-car" / "summary.json").read_text())["statistics"]
    assert statistics == summary["statistics"] and set(statistics["comparisons"]) == {"SAC+HER+MEGA (baseline)"}
    area = statistics["methods"]["SAC+HER (scratch)"]["area"]
    assert area["ci"][0] <= area["value"] <= area["ci"][1]
    assert "area gain" in format_table(summary) and "| baseline |" in format_table(summary)


def test_demo_tiny(tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """
    The demo's code path at a tiny budget (the real demo takes minutes): few steps, and its budgets' evaluations made
    smoke-sized (10 of 10 episodes a stage took most of this test's time).
    """
    for name in (BUDGET, BONUS_BUDGET):
        monkeypatch.setitem(BUDGETS, name, dataclasses.replace(BUDGETS[name], n_evals=2, eval_episodes=2))
    demo_main(
        ["--root", str(tmp_path), "--source-steps", "300", "--steps", "200", "--bonus-seeds", "1", "--bonus-steps", "200"]
    )
    out = capsys.readouterr().out
    assert "PILoT" in out and "SAC+HER" in out and "Wall time" in out
    assert "1 seed(s) cannot tell a gain from noise" in out and "committed 10-seed run" in out
    for challenge in ("high-dim-action", "maze-car-shipped"):
        assert (tmp_path / challenge / "success.png").stat().st_size > 10_000


def test_only_stages_keeps_what_they_read_from(capsys: pytest.CaptureFixture[str]) -> None:
    """``--stages her`` runs the baseline alone (a budget sized before any PILoT run); a target brings its source."""
    challenge = CHALLENGES["maze-car"]
    assert [stage.name for stage in only_stages(challenge, ["her"]).stages] == ["her"]
    assert [stage.name for stage in only_stages(challenge, ["pilot"]).stages] == ["source", "distill", "pilot"]
    with pytest.raises(SystemExit):
        challenges_main(["maze-car", "--stages", "baseline"])
    assert "['baseline'] are not stages of maze-car" in capsys.readouterr().err


def test_complex_morph_recipe_is_every_methods(tmp_path: Path) -> None:
    """At the cpu budget every Ant method trains with the same recipe (goal-relative inputs, lean SAC): only the bonus
    and MEGA's wrapper differ; the class in ``policy_kwargs`` reaches the zoo as an expression it evaluates."""
    from sb3_pilot.common.torch_layers import GoalRelativeExtractor
    from sb3_pilot.experiments.challenges.definitions import BUDGETS
    from sb3_pilot.experiments.challenges.stages import Import, StageContext, zoo_hyperparams

    assert eval(repr(Import("sb3_pilot.common.torch_layers", "GoalRelativeExtractor"))) is GoalRelativeExtractor
    challenge = CHALLENGES["complex-morph"]
    ctx = StageContext(tmp_path, 0, BUDGETS["cpu"], challenge.steps["cpu"], challenge.recipe)
    ctx.outputs = {stage.name: stage.output(tmp_path / stage.name) for stage in challenge.stages}

    def params(name: str) -> dict[str, Any]:
        stage = next(stage for stage in challenge.stages if stage.name == name)
        config = stage.config(ctx, tmp_path / name)
        args = config["zoo"]
        assert args[args.index("--algo") + 1] == "lean_sac" and args[args.index("-n") + 1] == "300000"
        values = zoo_hyperparams(config)
        bonus_and_mega = ("env_wrapper", "replay_buffer_class", "callback", "vec_env_wrapper")
        return {key: value for key, value in values.items() if key not in bonus_and_mega}

    her = params("her")
    assert her["policy_kwargs"]["features_extractor_class"] is GoalRelativeExtractor
    assert her["n_envs"] == 2 and her["gamma"] == 0.98
    assert all(params(name) == her for name in ("pilot", "pilot_disp", "mega"))


@pytest.mark.parametrize("name", ["high-dim-action-push", "high-dim-action"])
def test_only_the_push_source_learns_its_temperature_from_a_tenth(name: str, tmp_path: Path) -> None:
    """Fetch-Push's UDPO source starts its temperature at 0.1 (from 1 it ran away on 2 of 7 seeds); its target UDPO
    and the Fetch-Reach challenge keep SB3's initial temperature."""
    from sb3_pilot.experiments.challenges.definitions import BUDGETS
    from sb3_pilot.experiments.challenges.stages import StageContext

    challenge = CHALLENGES[name]
    ctx = StageContext(tmp_path, 0, BUDGETS["cpu"], challenge.steps["cpu"], challenge.recipe)
    ctx.outputs = {stage.name: stage.output(tmp_path / stage.name) for stage in challenge.stages}
    ent_coef = {
        stage.name: [arg for arg in stage.zoo_args(ctx, tmp_path / stage.name) if arg.startswith("ent_coef:")]
        for stage in challenge.stages
    }
    push = name == "high-dim-action-push"
    assert ent_coef == {"source": ["ent_coef:'auto_0.1'"] if push else [], "pilot": [], "her": []}


def test_a_changed_preset_makes_a_stage_stale(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A stage's hash covers the conf file's entry under its command: a stage trained under another preset reruns."""
    from sb3_pilot.experiments.challenges import stages
    from sb3_pilot.experiments.challenges.definitions import BUDGETS
    from sb3_pilot.experiments.zoo import hyperparams_dir

    challenge = CHALLENGES["high-dim-action"]
    source = next(stage for stage in challenge.stages if stage.name == "source")
    ctx = stages.StageContext(tmp_path, 0, BUDGETS["cpu"], challenge.steps["cpu"], challenge.recipe)

    def digest() -> str:
        return stages.config_hash(source.config(ctx, tmp_path / "source"), [])

    before = digest()
    conf = tmp_path / "hyperparams"
    shutil.copytree(hyperparams_dir(), conf)
    monkeypatch.setattr(stages, "hyperparams_dir", lambda: conf)
    assert digest() == before  # the same presets elsewhere
    path = conf / source.conf_file_at(ctx)
    presets = yaml.safe_load(path.read_text())
    presets[source.env_id]["planner_coef"] *= 2
    path.write_text(yaml.safe_dump(presets))
    assert digest() != before


def test_recorded_seeds_outlive_their_models(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A fresh clone has summary.json but not the gitignored models: more seeds run only the new ones."""
    challenge = only_stages(CHALLENGES["maze-car"], ["her", "pilot_disp"])
    first = run_challenge(challenge, "smoke", seeds=[0], root=tmp_path)
    shutil.rmtree(tmp_path / "maze-car" / "models")
    capsys.readouterr()
    both = run_challenge(challenge, "smoke", seeds=[0, 1], root=tmp_path)
    out = capsys.readouterr().out
    assert out.count("recorded in summary.json") == 4 and "seed 1 her: finished" in out and "seed 0 her: finished" not in out
    for method, result in both["methods"].items():
        assert [run["seed"] for run in result["runs"]] == [0, 1]
        assert result["runs"][0] == first["methods"][method]["runs"][0]
    assert both["stages"]["seed_0/her"] == first["stages"]["seed_0/her"]
    # a new stage reading from a recorded one (the planner, whose file is gone) runs it again, and what it reads from
    run_challenge(only_stages(CHALLENGES["maze-car"], ["her", "pilot_disp", "pilot"]), "smoke", seeds=[0], root=tmp_path)
    out = capsys.readouterr().out
    assert "seed 0 source: finished" in out and "seed 0 distill: finished" in out and "seed 0 pilot: finished" in out
    assert out.count("recorded in summary.json") == 2  # her and pilot_disp: nothing reads from them
