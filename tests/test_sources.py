"""The source-task benchmark (UDPO + HER vs SAC + HER): its stages, verdicts and a smoke run."""

from pathlib import Path

from benchmarks.sources import (
    SAC_HER,
    SOURCE_TASKS,
    UDPO_HER,
    main,
    source_challenge,
    table,
    verdict,
)
from sb3_pilot.experiments.challenges import CHALLENGES, stage_graph
from sb3_pilot.experiments.challenges.definitions import BUDGETS
from sb3_pilot.experiments.challenges.stages import StageContext, zoo_hyperparams


def test_every_source_task_has_two_independent_stages() -> None:
    for env_id in SOURCE_TASKS:
        challenge = source_challenge(env_id)
        assert stage_graph(challenge, [0, 1]) == {f"seed_{s}/{n}": () for s in (0, 1) for n in ("udpo", "her")}
        assert [stage.method for stage in challenge.stages] == [UDPO_HER, SAC_HER]
        assert bool(challenge.recipe) == ("Fetch" in env_id or env_id == "Pilot/Reacher-v0")


def test_reacher_recipe_is_the_fetch_one_with_one_env(tmp_path: Path) -> None:
    """Reacher: RL-Zoo's FetchReach settings with VecNormalize and one env, both methods, 40k steps at the cpu budget."""
    challenge, fetch = source_challenge("Pilot/Reacher-v0"), source_challenge("Pilot/FetchReach-v0")
    assert challenge.steps["cpu"] == {"udpo": 40_000, "her": 40_000}
    recipe = StageContext(tmp_path, 0, BUDGETS["cpu"], challenge.steps["cpu"], challenge.recipe)
    fetch_recipe = StageContext(tmp_path, 0, BUDGETS["cpu"], fetch.steps.get("cpu", {}), fetch.recipe)
    keys = ("gamma", "learning_rate", "batch_size", "learning_starts", "policy_kwargs", "normalize")
    for stage, fetch_stage in zip(challenge.stages, fetch.stages, strict=True):
        reacher = zoo_hyperparams(stage.config(recipe, tmp_path / stage.name))
        assert reacher["n_envs"] == 1 and reacher["normalize"] is True
        fetch_values = zoo_hyperparams(fetch_stage.config(fetch_recipe, tmp_path / stage.name))
        assert {key: reacher[key] for key in keys} == {key: fetch_values[key] for key in keys}


def test_fetch_push_recipe_reaches_the_zoo(tmp_path: Path) -> None:
    """FetchPush at the cpu budget: one env, a 50k-step warm-up and target entropy 0 for both methods, UDPO with the
    linearised entropy term and lambda 1e-4, 150k steps; the same recipe as the High-Dim Push challenge."""
    challenge = source_challenge("Pilot/FetchPush-v0")
    assert challenge.recipe == CHALLENGES["high-dim-action-push"].recipe == "fetch_push"
    assert challenge.steps["cpu"] == {"udpo": 150_000, "her": 150_000}
    ctx = StageContext(tmp_path, 0, BUDGETS["cpu"], challenge.steps["cpu"], challenge.recipe, {})
    udpo, her = (zoo_hyperparams(stage.config(ctx, tmp_path / stage.name)) for stage in challenge.stages)
    for values in (udpo, her):
        assert (values["n_envs"], values["learning_starts"], values["target_entropy"], values["tau"]) == (1, 50000, 0.0, 0.05)
    assert (udpo["planner_coef"], udpo["entropy_term"]) == (0.0001, "linearised") and "planner_coef" not in her


def test_maze2d_trains_on_uniform_goals_and_is_evaluated_on_the_far_goal(tmp_path: Path) -> None:
    challenge = source_challenge("Pilot/Maze2D-v0")
    ctx = StageContext(tmp_path, 0, BUDGETS["cpu"], {}, challenge.recipe, {})
    for stage in challenge.stages:
        args = stage.zoo_args(ctx, tmp_path / stage.name)
        assert args[args.index("--env-kwargs") + 1] == "goal_distribution:'uniform'"
        assert args[args.index("--eval-env-kwargs") + 1] == "goal_distribution:'far'"
        assert not any(arg.startswith("policy_kwargs") for arg in args)  # SB3's 256x256 networks


def test_verdict() -> None:
    """Issue 21's rule on the IQM steps to 90% (censored seeds included): UDPO as fast as HER within 1.1x."""

    def stats(steps: int, reached: int, seeds: int = 5) -> dict:
        return {"seeds": seeds, "steps_to_90": {"value": steps, "ci": [steps, steps], "reached": reached}}

    assert verdict(stats(2000, 5), stats(2000, 5)) == "as fast as HER (IQM steps to 90% 1.00x HER's)"
    assert verdict(stats(2200, 5), stats(2000, 5)).startswith("as fast as HER (IQM steps to 90% 1.10x")
    assert verdict(stats(2400, 5), stats(2000, 5)).startswith("slower than HER (IQM steps to 90% 1.20x")
    assert verdict(stats(1000, 3), stats(2000, 0)) == (
        "as fast as HER (HER never reached 90%: IQM steps to 90% at most 0.50x HER's)"
    )
    assert verdict(stats(2200, 0), stats(1000, 3)) == (
        "slower than HER (UDPO never reached 90%: IQM steps to 90% at least 2.20x HER's)"
    )
    assert verdict(stats(11000, 0), stats(11000, 0)) == "neither reached 90% at this budget"
    assert verdict(stats(2000, 2, seeds=2), stats(2000, 2, seeds=2)).startswith("too few seeds (2) for a verdict")
    interval = {"value": 1.2, "ci": [0.9, 1.5]}
    assert verdict(stats(2400, 5), stats(2000, 5), interval) == "slower than HER (IQM steps to 90% 1.20x HER's [0.90, 1.50])"


def test_table_statistics() -> None:
    """The table's IQM, intervals and verdict come from statistics.method_statistics of each method's runs."""
    steps = [1000 * k for k in range(1, 11)]
    fast, slow = [0.0, 0.5, 0.9, *[1.0] * 7], [0.0, 0.0, 0.5, 0.9, *[1.0] * 6]
    summary = {
        "target_env": "Pilot/Maze2D-v0",
        "seeds": [0, 1, 2],
        "methods": {
            UDPO_HER: {"runs": [{"timesteps": steps, "success_rate": slow}] * 3, "mean": {"timesteps": steps}},
            SAC_HER: {"runs": [{"timesteps": steps, "success_rate": fast}] * 3, "mean": {"timesteps": steps}},
        },
    }
    rows = table([summary], reps=50).splitlines()[2:]
    assert rows[0].startswith("| Pilot/Maze2D-v0 (3) | UDPO+HER | 10000 | 3000 [3000, 3000] (3/3) | 4000 [4000, 4000] (3/3) |")
    assert "| 1.00 [1.00, 1.00] | 0.74 [0.74, 0.74] | slower than HER (IQM steps to 90% 1.33x HER's [1.33, 1.33]) |" in rows[0]
    assert rows[1].startswith("|  | SAC+HER | 10000 | 2000 [2000, 2000] (3/3) | 3000 [3000, 3000] (3/3) |")


def test_sources_smoke(tmp_path: Path) -> None:
    main(["--budget", "smoke", "--tasks", "Pilot/Maze2D-v0", "--root", str(tmp_path), "--jobs", "2"])
    text = (tmp_path / "table.md").read_text()
    assert "Pilot/Maze2D-v0 (1)" in text and UDPO_HER in text and SAC_HER in text
    assert (tmp_path / "source-maze2d" / "summary.json").is_file()
