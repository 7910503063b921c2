"""The source-task benchmark (UDPO + HER vs SAC + HER): its stages, verdicts and a smoke run."""

from pathlib import Path

from sb3_pilot.experiments.benchmarks.sources import SAC_HER, SOURCE_TASKS, UDPO_HER, main, source_challenge, verdict
from sb3_pilot.experiments.challenges import stage_graph


def test_every_source_task_has_two_independent_stages() -> None:
    for env_id in SOURCE_TASKS:
        challenge = source_challenge(env_id)
        assert stage_graph(challenge, [0, 1]) == {f"seed_{s}/{n}": () for s in (0, 1) for n in ("udpo", "her")}
        assert [stage.method for stage in challenge.stages] == [UDPO_HER, SAC_HER]
        assert bool(challenge.fast_hyperparams) == ("Fetch" in env_id)


def test_verdict() -> None:
    def mean(to_50: int | None, to_90: int | None) -> dict:
        return {"steps_to_50": to_50, "steps_to_90": to_90}

    assert verdict(mean(1000, 2000), mean(1000, 2000)).startswith("as fast as HER (90% at 1.00x")
    assert verdict(mean(1000, 3000), mean(1000, 2000)).startswith("slower than HER (90% at 1.50x")
    assert verdict(mean(1000, None), mean(2000, None)).startswith("as fast as HER (50% at 0.50x")
    assert verdict(mean(None, None), mean(2000, None)) == "HER only reached 50%"
    assert verdict(mean(None, None), mean(None, None)) == "neither reached 50% at this budget"


def test_sources_smoke(tmp_path: Path) -> None:
    main(["--budget", "smoke", "--tasks", "Pilot/Maze2D-v0", "--root", str(tmp_path), "--jobs", "2"])
    text = (tmp_path / "table.md").read_text()
    assert "Pilot/Maze2D-v0 (1)" in text and UDPO_HER in text and SAC_HER in text
    assert (tmp_path / "source-maze2d" / "summary.json").is_file()
