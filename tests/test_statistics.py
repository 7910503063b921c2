"""The rliable statistics of the challenges' learning curves, on synthetic curves whose answer is known."""

from __future__ import annotations

import numpy as np
import pytest

from sb3_pilot.experiments.statistics import (
    CONFIRM_SEEDS,
    MIN_SEEDS,
    aggregate_name,
    compare,
    format_estimate,
    format_seeds,
    iqm,
    method_statistics,
    pointwise_iqm,
    run_scores,
    shared_sources,
    summary_statistics,
    verdict,
)

STEPS = list(range(2000, 20_001, 2000))
REPS = 500  # enough for the clear cases here, and fast


def ramps(starts: np.ndarray) -> list[dict]:
    """Runs whose success rises linearly from 0 at ``start`` to 1 over 6000 steps."""
    return [{"timesteps": STEPS, "success_rate": np.clip((np.array(STEPS) - start) / 6000, 0, 1).tolist()} for start in starts]


def test_run_scores() -> None:
    scores = run_scores([100, 200, 300, 400], [0.0, 0.5, 0.8, 1.0])
    assert scores == {
        "area": pytest.approx(0.575),
        "final_success": 1.0,
        "censored_at": 500.0,
        "steps_to_50": 200.0,
        "steps_to_90": 400.0,
    }
    assert run_scores([0], [0.3])["steps_to_50"] == run_scores([0], [0.3])["censored_at"] == 1.0  # never reached
    with pytest.raises(ValueError, match="as many"):
        run_scores([100, 200], [0.5])
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        run_scores([100], [1.5])


def test_a_clear_gain_is_confirmed_and_no_gain_is_not() -> None:
    rng = np.random.default_rng(0)
    her = ramps(rng.uniform(4000, 16_000, size=10))
    pilot = ramps(rng.uniform(0, 4000, size=10))
    result = compare(pilot, her, reps=REPS)
    assert result["verdict"].startswith("confirmed")
    assert result["area_gain"]["ci"][0] > 0 and result["probability_of_improvement"]["value"] > 0.9
    ratio = result["steps_to_90_ratio"]
    assert ratio["value"] < 0.6 and ratio["ci"][0] <= ratio["value"] <= ratio["ci"][1] < 1
    assert compare(her, pilot, reps=REPS)["verdict"].startswith("worse")
    same = compare(her, her, reps=REPS)  # identical curves: an interval around 0, never "confirmed"
    assert same["area_gain"]["value"] == 0 and same["probability_of_improvement"]["value"] == 0.5
    assert same["verdict"].startswith("no gain shown")
    low, high = same["steps_to_90_ratio"]["ci"]
    assert same["steps_to_90_ratio"]["value"] == 1 and low < 1 < high
    never = [{"timesteps": STEPS, "success_rate": [0.0] * len(STEPS)}] * 3
    assert compare(never, never, reps=REPS)["steps_to_90_ratio"] is None  # neither reached 90%: no ratio
    # the same gain on two seeds: no verdict at all
    assert compare(pilot[:2], her[:2], reps=REPS)["verdict"].startswith("too few seeds (2)")


def test_verdict_wording() -> None:
    assert verdict({"value": 0.1, "ci": [-0.05, 0.3]}, 10) == "a hint: area gain +0.10 [-0.05, +0.30] includes 0"
    assert verdict({"value": -0.1, "ci": [-0.3, 0.05]}, 10).startswith("no gain shown")
    above, below = {"value": 0.3, "ci": [0.2, 0.4]}, {"value": -0.3, "ci": [-0.4, -0.2]}
    assert (MIN_SEEDS, CONFIRM_SEEDS) == (3, 5)
    assert verdict(above, 5) == "confirmed: area gain +0.30 [+0.20, +0.40]"
    assert verdict(above, 4) == "a hint: area gain +0.30 [+0.20, +0.40] above 0 on 4 seeds per method (5 needed)"
    assert verdict(below, 5).startswith("worse than SAC+HER")
    assert verdict(below, 3) == "no gain shown: area gain -0.30 [-0.40, -0.20] below 0 on 3 seeds per method (5 needed)"
    assert verdict(above, 2).startswith("too few seeds (2)")


def test_a_bound_near_zero_is_printed_with_its_sign() -> None:
    # Fetch-Reach-Image's verdict run: an interval just above 0 must not read as touching it (+0.00)
    assert verdict({"value": 0.0142, "ci": [0.0033, 0.0392]}, 5) == "confirmed: area gain +0.014 [+0.003, +0.039]"
    assert verdict({"value": 0.0, "ci": [0.0, 0.0]}, 1).endswith("area gain +0.00 [+0.00, +0.00]")  # exact zeros
    assert format_estimate({"value": 0.00004, "ci": [-0.2, 0.2]}, signed=True) == "+0.0000 [-0.2000, +0.2000]"  # at most 4
    assert format_estimate({"value": 0.004, "ci": [0.0, 0.2]}) == "0.00 [0.00, 0.20]"  # a level: its fixed decimals


def test_iqm_of_under_four_seeds_is_the_mean() -> None:
    """rliable's IQM (SciPy's trim_mean, 25%) cuts int(n / 4) runs at each end: none under 4, labelled the mean."""
    for n in range(1, 9):
        scores = np.arange(n, dtype=np.float64) ** 2  # skewed: any cut moves the mean
        cuts = iqm(scores) != pytest.approx(scores.mean())
        assert aggregate_name(n) == ("IQM" if n >= 4 else "mean") and cuts == (n >= 4), n
    assert format_seeds(3, 3) == "3 (3 sources)" and format_seeds(6, 1) == "6 (1 source)"
    assert format_seeds(6, 0) == "6" and format_seeds(3, None) == "3 (sources unknown)"


def test_iqm_is_rliables_to_the_last_bit() -> None:
    """
    ``iqm`` skips SciPy's per-call checks, not its arithmetic: on scores of every shape the bootstraps give it (seeds,
    a column of them, ties, large offsets) it returns rliable's ``aggregate_iqm`` exactly, NaN where that is NaN.
    """
    from rliable import metrics

    rng = np.random.default_rng(0)
    for size in [*range(1, 33), 100]:
        for scores in (
            rng.random(size),
            rng.integers(0, 5, size) / 4.0,  # success rates of 4 episodes: many ties
            rng.normal(1e6, 1e3, size),
            rng.random((size, 3)),
        ):
            assert iqm(scores) == float(metrics.aggregate_iqm(scores)), scores
    assert np.isnan(iqm(np.array([0.5, np.nan, 1.0]))) and np.isnan(iqm(np.array([])))


@pytest.mark.parametrize(
    ("seeds", "gain", "expected"),
    [(3, True, "a hint"), (4, True, "a hint"), (5, True, "confirmed"), (6, True, "confirmed"), (6, False, "no gain shown")],
)
def test_verdict_counts_seeds(seeds: int, gain: bool, expected: str) -> None:
    """A clear gain on 3 or 4 seeds per method is a hint, on 5 or more confirmed; no gain on 6 seeds is none."""
    rng = np.random.default_rng(seeds)
    her = ramps(rng.uniform(10_000, 16_000, size=seeds))
    pilot = ramps(rng.uniform(0, 2000, size=seeds)) if gain else her
    comparison = compare(pilot, her, reps=200)
    assert comparison["verdict"].startswith(expected), comparison["verdict"]
    assert (comparison["area_gain"]["ci"][0] > 0) == gain  # the interval excludes 0 whenever the gain is clear
    assert comparison["seeds"] == {"method": seeds, "baseline": seeds}


def test_summary_statistics_state_seeds_sources_and_the_mean() -> None:
    """Per method: its seeds, its distinct sources (as the summary records them; None for an older summary) and
    whether its IQM is a mean."""
    rng = np.random.default_rng(0)
    runs = {"PILoT": ramps(rng.uniform(0, 2000, size=3)), "SAC+HER": ramps(rng.uniform(10_000, 16_000, size=4))}
    summary = {"methods": {method: {"runs": method_runs, "sources": 0} for method, method_runs in runs.items()}}
    summary["methods"]["PILoT"]["sources"] = 1  # every seed read one shipped source
    statistics = summary_statistics(summary, "SAC+HER", reps=50)
    pilot, her = statistics["methods"]["PILoT"], statistics["methods"]["SAC+HER"]
    assert (pilot["seeds"], pilot["sources"], pilot["aggregate"]) == (3, 1, "mean")
    assert (her["seeds"], her["sources"], her["aggregate"]) == (4, 0, "IQM")
    comparison = statistics["comparisons"]["PILoT"]
    assert comparison["seeds"] == {"method": 3, "baseline": 4} and comparison["verdict"].startswith("a hint")
    del summary["methods"]["PILoT"]["sources"]  # an older summary: no sources recorded
    assert summary_statistics(summary, "SAC+HER", reps=50)["methods"]["PILoT"]["sources"] is None


def test_a_method_is_compared_with_the_baseline_its_summary_names() -> None:
    """A guided controller's entry names the same controller unguided: its comparison is with that method, named in
    the verdict; the others are still compared with SAC+HER; a baseline is compared with none."""
    once = [{"timesteps": [0], "success_rate": [rate]} for rate in (0.3, 0.4, 0.5, 0.3, 0.4, 0.5)]
    never = [{"timesteps": [0], "success_rate": [rate]} for rate in (0.0, 0.0, 0.1, 0.0, 0.0, 0.0)]
    rng = np.random.default_rng(0)
    summary = {
        "methods": {
            "guided": {"runs": once, "baseline": "unguided", "sources": 6},
            "unguided": {"runs": never, "sources": 6},
            "SAC+HER": {"runs": ramps(rng.uniform(0, 2000, size=6)), "sources": 0},
        }
    }
    comparisons = summary_statistics(summary, "SAC+HER", reps=200)["comparisons"]
    guided = comparisons["guided"]
    assert guided["baseline"] == "unguided" and guided["area_gain"]["value"] == pytest.approx(0.4)  # IQMs 0.4 and 0
    assert guided["verdict"].startswith("confirmed: area gain +0.40") and guided["verdict"].endswith("over unguided")
    assert set(comparisons) == {"guided"}
    assert verdict({"value": -0.3, "ci": [-0.4, -0.2]}, 5, against="unguided").startswith("worse than unguided: area gain")
    summary["methods"]["guided"]["baseline"] = "gone"  # a baseline the summary lacks: the method is compared with none
    assert set(summary_statistics(summary, "SAC+HER", reps=50)["comparisons"]) == {"unguided"}  # a baseline no more


def test_a_seed_stopped_early_has_not_reached() -> None:
    """A shorter curve that never reached 90% counts as censored at its own next point, not as reached."""
    full = {"timesteps": [10, 20, 30, 40], "success_rate": [0.0, 0.5, 0.9, 1.0]}
    stopped = {"timesteps": [10, 20], "success_rate": [0.0, 0.5]}
    stats = method_statistics([full, stopped], reps=REPS)
    assert stats["steps_to_90"]["reached"] == 1 and stats["steps_to_90"]["censored_at"] == 50
    assert stats["steps_to_50"]["reached"] == 2


def test_a_budget_censors_every_run() -> None:
    """With the budget's censoring step, a run stopped early counts as one that never reached 90% in the budget."""
    full = {"timesteps": [10, 20, 30, 40], "success_rate": [0.0, 0.5, 0.9, 1.0]}
    stopped = {"timesteps": [10, 20], "success_rate": [0.0, 0.5]}
    assert run_scores(stopped["timesteps"], stopped["success_rate"], censored_at=50)["steps_to_90"] == 50
    stats = method_statistics([full, stopped, stopped], reps=REPS, censored_at=50)
    assert stats["steps_to_90"]["value"] == pytest.approx(130 / 3) and stats["steps_to_90"]["reached"] == 1  # 30, 50, 50
    assert compare([stopped] * 3, [full] * 3, reps=REPS, censored_at=50)["steps_to_90_ratio"]["value"] == pytest.approx(
        50 / 30
    )
    with pytest.raises(ValueError, match="past the last evaluated step"):
        run_scores(full["timesteps"], full["success_rate"], censored_at=40)


def test_method_statistics_and_pointwise_iqm() -> None:
    runs = ramps(np.array([0, 0, 0, 30_000]))  # three seeds at 90% by 8000, one never learns
    stats = method_statistics(runs, reps=REPS)
    assert stats["seeds"] == 4 and stats["steps_to_90"]["reached"] == 3 and stats["steps_to_90"]["censored_at"] == 22_000
    assert stats["aggregate"] == "IQM"  # 4 seeds: one cut at each end
    assert stats["final_success"]["value"] == 1.0  # the IQM trims the seed that never learned
    low, high = stats["area"]["ci"]
    assert low <= stats["area"]["value"] <= high
    center, interval = pointwise_iqm(np.array([run["success_rate"] for run in runs]), reps=REPS)
    assert center.shape == (len(STEPS),) and interval.shape == (2, len(STEPS))
    assert np.all(interval[0] <= center + 1e-9) and np.all(center <= interval[1] + 1e-9)
    assert method_statistics(runs, reps=REPS) == stats  # the bootstrap is seeded: the same intervals every time
    with pytest.raises(ValueError, match="reps"):
        method_statistics(runs, reps=0)
    with pytest.raises(ValueError, match="No runs"):
        method_statistics([])


def test_seeds_sharing_sources_are_at_most_a_hint() -> None:
    """Ten seeds that read one shipped source: the target's seed noise, not the source's; a hint, said so."""
    above, below = {"value": 0.3, "ci": [0.2, 0.4]}, {"value": -0.3, "ci": [-0.4, -0.2]}
    assert verdict(above, 10, sources=1) == (
        "a hint: area gain +0.30 [+0.20, +0.40] above 0 on 10 seeds per method of 1 source (5 needed)"
    )
    assert verdict(above, 3, sources=3).endswith("on 3 seeds per method of 3 sources (5 needed)")
    assert verdict(below, 10, sources=4).startswith("no gain shown: area gain -0.30 [-0.40, -0.20] below 0 on 10 seeds")
    assert verdict(above, 5, sources=5) == verdict(above, 5, sources=0) == "confirmed: area gain +0.30 [+0.20, +0.40]"
    assert verdict(above, 10, sources=None).endswith("on 10 seeds per method of unrecorded sources (5 needed)")
    # the fewest sources of the sides that read any (SAC+HER reads none: 0); a side not recorded (None): unknown
    assert (shared_sources(6, 0), shared_sources(1, 10), shared_sources(0, 0), shared_sources(None, 3)) == (6, 1, 0, None)
    # through a summary: the method's recorded sources reach its verdict
    pilot, her = ramps(np.linspace(0, 2000, 6)), ramps(np.linspace(8000, 10_000, 6))
    summary = {"methods": {"PILoT": {"runs": pilot, "sources": 1}, "HER": {"runs": her, "sources": 0}}}
    comparison = summary_statistics(summary, "HER", reps=REPS)["comparisons"]["PILoT"]
    assert comparison["verdict"].startswith("a hint") and "of 1 source (5 needed)" in comparison["verdict"]
    summary["methods"]["PILoT"]["sources"] = 6
    assert summary_statistics(summary, "HER", reps=REPS)["comparisons"]["PILoT"]["verdict"].startswith("confirmed")
