"""
Statistics of a challenge's learning curves that can tell a gain from seed noise, with ``rliable`` (Agarwal et al.,
"Deep RL at the Edge of the Statistical Precipice", 2021): per method, the interquartile mean (IQM) over seeds of

- ``area``: the area under the success curve, the mean of the evaluated success rates (the evaluations are evenly
  spaced, so this is the area under the curve over the budget, in [0, 1]);
- ``final_success``: the success rate of the last evaluation;
- ``steps_to_50`` / ``steps_to_90``: the first evaluated step whose success rate reaches 50% / 90%; a seed that
  never does counts as one evaluation interval past the budget (``censored_at``), and ``reached`` says how many did;

each with its stratified-bootstrap 95% interval (a zero-shot method has one evaluation: its area is its success
rate). Each PILoT method is compared with SAC+HER, or with the method its summary entry names as its ``baseline``
(a guided controller with the same controller unguided), on the area: the
probability of improvement ``P(area_PILoT > area_HER)`` and the gain ``IQM(area_PILoT) - IQM(area_HER)``, with their
bootstrap intervals (seeds of the two methods resampled independently), and on the pace: the ratio
``IQM(steps_to_90_PILoT) / IQM(steps_to_90_HER)`` with its interval (a censored seed makes its side's IQM a bound).

The verdict (:func:`verdict`) counts seeds: "confirmed" needs at least :data:`CONFIRM_SEEDS` seeds per method and an
interval of the gain above 0 ("worse than SAC+HER": below 0); with fewer, a gain is at most "a hint", and under
:data:`MIN_SEEDS` there is no verdict. It counts sources too: seeds that read fewer than :data:`CONFIRM_SEEDS`
distinct sources, or sources not recorded, give at most "a hint", however many seeds there are. The IQM cuts
``int(n / 4)`` runs at each end (SciPy's ``trim_mean``, which rliable calls): under 4 seeds it cuts none and is the
plain mean, which ``aggregate`` says (:func:`aggregate_name`).
A method's ``sources`` (in the summary, when its runner recorded them) is the number of distinct stages its seeds
read from (a trained source per seed, or one shipped planner or controller for all): seeds that share one source
leave the source's own variance out of the interval.

Where the summary records how each seed's trained source learned its own task (``source``, with ``learned`` per
seed), :func:`source_split_statistics` repeats the statistics of the methods that read it over the seeds whose source
learned, against the baseline's seeds, all of them (it reads no source). That subset is chosen after the fact, so
its verdict is at most "a hint" (:func:`verdict`'s ``subset``); the statistics over every seed stay the headline.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

# rliable (with arch, pandas and scipy.stats: ~1.5 s of CPU) is imported where it is used, so that the processes that
# import this module for its names (every challenge stage's) do not pay for it

#: Per-seed scores of a method, IQM-aggregated.
METRICS = ("area", "final_success", "steps_to_50", "steps_to_90")
#: Coverage of the intervals.
CONFIDENCE = 0.95
#: Bootstrap replications (rliable's default is 50000; its bootstrap runs each in Python: 2000 keep a summary's
#: statistics within seconds, and the 2.5% / 97.5% quantiles of 2000 draws within about 0.01 of success)
REPS = 2000
#: Fewer seeds than this per method: no verdict (a bootstrap over one or two seeds has no width to speak of).
MIN_SEEDS = 3
#: Fewer seeds than this per method: at most "a hint" (complete separation of 3 runs against 3 is p = 0.05 at best,
#: and a percentile bootstrap over 3 values gives intervals that are too narrow).
CONFIRM_SEEDS = 5
#: The fraction of runs the IQM cuts at each end (rliable's ``aggregate_iqm``: ``scipy.stats.trim_mean``).
IQM_CUT = 0.25
#: The most decimals of a signed estimate (a gain) whose nonzero numbers would otherwise print as 0.
SIGNED_DIGITS = 4


def aggregate_name(runs: int) -> str:
    """
    ``"IQM"``, or ``"mean"`` where the IQM of ``runs`` values cuts none (``int(IQM_CUT * runs) == 0``: under 4 runs).

    :param runs: the number of runs (seeds) aggregated
    """
    return "IQM" if int(IQM_CUT * runs) > 0 else "mean"


def format_seeds(seeds: int, sources: int | None) -> str:
    """
    A method's seed count and its number of distinct sources: ``3 (3 sources)``, ``3 (1 source)``; ``3`` alone for a
    method that reads no source (from scratch), ``3 (sources unknown)`` for a summary that did not record them.

    :param seeds: its seeds
    :param sources: its distinct sources (0: none; None: not recorded)
    """
    if sources == 0:
        return str(seeds)
    if sources is None:
        return f"{seeds} (sources unknown)"
    return f"{seeds} ({sources} source{'s' * (sources != 1)})"


def run_scores(timesteps: Sequence[int], success_rate: Sequence[float], censored_at: float | None = None) -> dict[str, float]:
    """
    The scores of one seed's learning curve (see the module doc).

    :param timesteps: the evaluated env steps (increasing)
    :param success_rate: the success rate of each evaluation, in [0, 1]
    :param censored_at: where a threshold never reached counts (None: one evaluation interval past the last step);
        give the budget's own to judge a run that stopped before the budget (it crashed, or was stopped) as one that
        ran to the budget without reaching it, not as one that would have reached it next
    :return: ``area``, ``final_success``, ``steps_to_50``, ``steps_to_90`` (censored at ``censored_at``) and
        ``censored_at``
    """
    if len(timesteps) == 0 or len(timesteps) != len(success_rate):
        raise ValueError(
            f"A learning curve needs as many (>= 1) steps as success rates, got {len(timesteps)} and {len(success_rate)}."
        )
    rates = np.asarray(success_rate, dtype=np.float64)
    if np.any((rates < 0) | (rates > 1)):
        raise ValueError(f"Success rates must lie in [0, 1], got {rates.tolist()}.")
    steps = np.asarray(timesteps, dtype=np.float64)
    if censored_at is None:
        censored_at = steps[-1] + (steps[-1] - steps[-2] if len(steps) > 1 else 1.0)
    elif censored_at <= steps[-1]:
        raise ValueError(f"censored_at ({censored_at}) must lie past the last evaluated step ({steps[-1]}).")
    scores = {"area": float(rates.mean()), "final_success": float(rates[-1]), "censored_at": float(censored_at)}
    for threshold in (0.5, 0.9):
        reached = np.flatnonzero(rates >= threshold)
        scores[f"steps_to_{round(100 * threshold)}"] = float(steps[reached[0]]) if len(reached) else float(censored_at)
    return scores


def first_steps(runs: Sequence[dict[str, Any]], last: int) -> list[dict[str, Any]]:
    """
    The runs' learning curves cut after ``last`` env steps (a shorter budget's window of longer runs).

    :param runs: runs with ``seed``, ``timesteps`` and ``success_rate``
    :param last: the last env step kept
    """
    cut = []
    for run in runs:
        n = sum(step <= last for step in run["timesteps"])
        cut.append({"seed": run["seed"], "timesteps": run["timesteps"][:n], "success_rate": run["success_rate"][:n]})
    return cut


def format_estimate(entry: dict[str, Any], digits: int = 2, signed: bool = False) -> str:
    """
    ``value [low, high]`` of a statistic.

    :param entry: ``{"value", "ci"}``
    :param digits: decimals
    :param signed: a gain's form, ``+0.12 [+0.03, +0.20]``, with more decimals (up to :data:`SIGNED_DIGITS`) where
        a nonzero number would read as +0.00 or -0.00: an interval just above 0 must not print as if it touched 0
    """
    values = [entry["value"], *entry["ci"]]
    while signed and digits < SIGNED_DIGITS and any(v != 0 and round(abs(v), digits) == 0 for v in values):
        digits += 1
    value, low, high = (f"{v:{'+' if signed else ''}.{digits}f}" for v in values)
    return f"{value} [{low}, {high}]"


def _estimates(data: Any, func: Callable[..., np.ndarray], seed: int, reps: int) -> tuple[np.ndarray, np.ndarray]:
    """
    rliable's ``get_interval_estimates`` (percentile method) on one entry, reproducible.

    :param data: scores of shape (seeds, columns), or a list of them (resampled independently)
    :param func: the statistics of the scores, a 1D array
    :param seed: the bootstrap's random seed
    :param reps: bootstrap replications
    :return: the point estimates and their intervals (2, ...)
    """
    if reps < 1:
        raise ValueError(f"reps must be a positive number of bootstrap replications, got {reps!r}.")
    # rliable's StratifiedBootstrap draws its indices from NumPy's global generator (np.random.choice), whatever
    # random_state it is given: seed that one for the call, and put its state back afterwards
    from rliable import library

    state = np.random.get_state()
    np.random.seed(seed)
    try:
        with warnings.catch_warnings():  # rliable passes arch a RandomState, which arch 7 deprecates
            warnings.simplefilter("ignore", FutureWarning)
            points, intervals = library.get_interval_estimates(
                {"x": data}, func, reps=reps, confidence_interval_size=CONFIDENCE, random_state=np.random.RandomState(seed)
            )
    finally:
        np.random.set_state(state)
    return points["x"], intervals["x"]


def _interval(scores: Any, func: Callable[..., float], seed: int, reps: int) -> dict[str, Any]:
    """
    Point estimate and stratified-bootstrap interval of a scalar statistic of per-seed scores.

    :param scores: one array of per-seed scores, or a list of two (resampled independently)
    :param func: the statistic of the scores
    :param seed: the bootstrap's random seed
    :param reps: bootstrap replications
    """
    if isinstance(scores, list):
        data: Any = [np.asarray(array, dtype=np.float64)[:, None] for array in scores]
    else:
        data = np.asarray(scores, dtype=np.float64)[:, None]
    points, intervals = _estimates(data, lambda *arrays: np.array([func(*arrays)]), seed, reps)
    return {"value": float(points[0]), "ci": [float(intervals[0, 0]), float(intervals[1, 0])]}


def iqm(scores: np.ndarray) -> float:
    """
    Interquartile mean of per-seed scores: rliable's ``aggregate_iqm``, SciPy's ``trim_mean(scores, IQM_CUT,
    axis=None)``, computed as SciPy computes it (the same partition and mean, so the same floating-point result) but
    without SciPy's checks of its arguments, which took most of a bootstrap's time (it calls this 10^4-10^5 times).

    :param scores: the scores (flattened)
    :return: their IQM; NaN if there are none or one is NaN (as SciPy)
    """
    values = np.asarray(scores).ravel()
    if values.size == 0 or np.isnan(values).any():
        return float("nan")
    low = int(IQM_CUT * values.size)
    high = values.size - low
    return float(np.mean(np.partition(values, (low, high - 1))[low:high]))


def method_statistics(
    runs: Sequence[dict[str, Any]], seed: int = 0, reps: int = REPS, censored_at: float | None = None
) -> dict[str, Any]:
    """
    IQM over seeds and its interval for each of :data:`METRICS`.

    :param runs: the method's runs, each with ``timesteps`` and ``success_rate`` (``summary.json``'s ``runs``)
    :param seed: the bootstrap's random seed
    :param reps: bootstrap replications
    :param censored_at: every run's censoring step (:func:`run_scores`; None: each run's own)
    :return: ``{"seeds": n, "aggregate": "IQM" or "mean", metric: {"value", "ci"}, ...}`` (:func:`aggregate_name`);
        the steps' entries also hold ``reached`` and ``censored_at``
    """
    if not runs:
        raise ValueError("No runs to aggregate.")
    per_run = [run_scores(run["timesteps"], run["success_rate"], censored_at) for run in runs]
    result: dict[str, Any] = {"seeds": len(runs), "aggregate": aggregate_name(len(runs))}
    for metric in METRICS:
        values = np.array([scores[metric] for scores in per_run])
        result[metric] = _interval(values, iqm, seed, reps)
        if metric.startswith("steps_to"):
            # each seed against its own censoring point: a seed stopped early has not reached what it never showed
            reached = sum(scores[metric] < scores["censored_at"] for scores in per_run)
            result[metric].update(reached=int(reached), censored_at=max(scores["censored_at"] for scores in per_run))
    return result


def shared_sources(*sources: int | None) -> int | None:
    """
    The fewest distinct sources the seeds of the compared methods read (:func:`verdict`'s ``sources``).

    :param sources: each method's distinct sources (0: it reads none; None: not recorded)
    :return: the fewest of those above 0; 0 where no method reads one; None where a method's were not recorded
    """
    if None in sources:
        return None
    return min((count for count in sources if count), default=0)


def verdict(
    gain: dict[str, Any], seeds: int, subset: str | None = None, against: str | None = None, sources: int | None = 0
) -> str:
    """
    The verdict on "the PILoT method learns the target faster than SAC+HER" (or does better than ``against``) from
    the gain in area: "confirmed" when its interval lies above 0 on at least :data:`CONFIRM_SEEDS` seeds per method
    that read as many distinct sources, "worse than SAC+HER" when it lies below 0 on as many; "a hint" when only the
    estimate is above 0, or the interval on fewer seeds or sources or on a subset of the seeds chosen after the fact;
    "no gain shown" otherwise; no verdict under :data:`MIN_SEEDS` seeds.

    :param gain: ``{"value", "ci"}`` of ``IQM(area_PILoT) - IQM(area_HER)``
    :param seeds: the fewest seeds of the two methods
    :param subset: which seeds the PILoT method's are, where they were chosen after the fact (e.g. "the seeds whose
        source learned"); said in the verdict, which is then at most "a hint"
    :param against: the method compared with, where it is not SAC+HER (named in the verdict)
    :param sources: the fewest distinct sources the seeds of either method read (:func:`shared_sources`; 0: neither
        reads one); fewer than :data:`CONFIRM_SEEDS`, or None (not recorded), make the verdict at most "a hint"
    """
    value, (low, high) = gain["value"], gain["ci"]
    gain_text = f"area gain {format_estimate(gain, signed=True)}"
    interval = gain_text + (f" over {against}" if against else "")
    chosen = f", a subset chosen after the fact ({subset})" if subset else ""
    if seeds < MIN_SEEDS:
        return f"too few seeds ({seeds}) for a verdict: {interval}{chosen}"
    shared = sources is None or 0 < sources < CONFIRM_SEEDS
    firm = seeds >= CONFIRM_SEEDS and not shared and not subset
    few = f"{seeds} seeds per method"
    if shared:
        few += " of unrecorded sources" if sources is None else f" of {sources} source{'s' * (sources != 1)}"
    if seeds < CONFIRM_SEEDS or shared:
        few += f" ({CONFIRM_SEEDS} needed)"
    if low > 0:
        return f"confirmed: {interval}" if firm else f"a hint: {interval} above 0 on {few}{chosen}"
    if high < 0:
        if firm:
            return f"worse than {against or 'SAC+HER'}: {gain_text}"
        return f"no gain shown: {interval} below 0 on {few}{chosen}"
    if value > 0:
        return f"a hint: {interval} includes 0{chosen}"
    return f"no gain shown: {interval}{chosen}"


def compare(
    pilot_runs: Sequence[dict[str, Any]],
    her_runs: Sequence[dict[str, Any]],
    seed: int = 0,
    reps: int = REPS,
    censored_at: float | None = None,
    subset: str | None = None,
    against: str | None = None,
    sources: int | None = 0,
) -> dict[str, Any]:
    """
    A PILoT method against SAC+HER (or another baseline) on the area under the success curve.

    :param pilot_runs: the PILoT method's runs
    :param her_runs: SAC+HER's runs
    :param seed: the bootstrap's random seed
    :param reps: bootstrap replications
    :param censored_at: every run's censoring step (:func:`run_scores`; None: each run's own)
    :param subset: which seeds ``pilot_runs`` are, where they were chosen after the fact (:func:`verdict`)
    :param against: the baseline's name where ``her_runs`` are not SAC+HER's (:func:`verdict`)
    :param sources: the fewest distinct sources either side's seeds read (:func:`verdict`)
    :return: ``probability_of_improvement``, ``area_gain`` and ``steps_to_90_ratio`` (``{"value", "ci"}``; the ratio
        is the IQM of PILoT's steps to 90% over HER's, censored seeds included, None when no seed of either reached
        90%), ``seeds`` (``{"method": n, "baseline": n}``) and ``verdict``
    """
    pilot_scores, her_scores = (
        [run_scores(run["timesteps"], run["success_rate"], censored_at) for run in runs] for runs in (pilot_runs, her_runs)
    )
    pilot, her = (np.array([scores["area"] for scores in side]) for side in (pilot_scores, her_scores))

    def improvement(x: np.ndarray, y: np.ndarray) -> float:
        from rliable import metrics

        return float(metrics.probability_of_improvement(x, y))

    def gain(x: np.ndarray, y: np.ndarray) -> float:
        return iqm(x) - iqm(y)

    def ratio(x: np.ndarray, y: np.ndarray) -> float:
        return iqm(x) / iqm(y)

    area_gain = _interval([pilot, her], gain, seed, reps)
    reached = any(scores["steps_to_90"] < scores["censored_at"] for scores in (*pilot_scores, *her_scores))
    pilot_steps, her_steps = (np.array([scores["steps_to_90"] for scores in side]) for side in (pilot_scores, her_scores))
    return {
        "probability_of_improvement": _interval([pilot, her], improvement, seed, reps),
        "area_gain": area_gain,
        "steps_to_90_ratio": _interval([pilot_steps, her_steps], ratio, seed, reps) if reached else None,
        "seeds": {"method": len(pilot), "baseline": len(her)},
        "verdict": verdict(area_gain, min(len(pilot), len(her)), subset, against, sources),
    }


def summary_statistics(summary: dict[str, Any], baseline: str, seed: int = 0, reps: int = REPS) -> dict[str, Any]:
    """
    The statistics of a challenge's ``summary.json``: every method's (:func:`method_statistics`, with the number of
    distinct sources its seeds read from where the summary records it, else None), every other method compared
    with its own ``baseline`` where its summary entry names one, else with ``baseline`` (SAC+HER) when the challenge
    has it (:func:`compare`) and, where the summary records its trained source's own learning, the same over the
    seeds whose source learned (:func:`source_split_statistics`).

    :param summary: the summary
    :param baseline: the method the others are compared with, where they name none
    :param seed: the bootstrap's random seed
    :param reps: bootstrap replications
    :return: ``{"confidence", "reps", "methods": {method: ...}, "comparisons": {method: ...}}`` (each comparison
        with the ``baseline`` it was made against), and ``source_learned`` where the summary has a ``source``
    """
    methods = summary["methods"]
    comparisons = {
        method: _compare_with(methods, result["runs"], result.get("sources"), against, baseline, seed, reps)
        for method, result in methods.items()
        if (against := _baseline_of(methods, method, baseline)) is not None
    }
    statistics = {
        "confidence": CONFIDENCE,
        "reps": reps,
        "bootstrap_seed": seed,
        "methods": {
            method: {**method_statistics(result["runs"], seed, reps), "sources": result.get("sources")}
            for method, result in methods.items()
        },
        "comparisons": comparisons,
    }
    if "source" in summary:
        statistics["source_learned"] = source_split_statistics(summary, baseline, seed, reps)
    return statistics


def _baseline_of(methods: dict[str, Any], method: str, default: str) -> str | None:
    """
    The method ``method`` is compared with: its summary entry's ``baseline``, else ``default``; None where that is
    not in the summary, or ``method`` is itself a baseline (``default``, or one another entry names).
    """
    if method == default or any(result.get("baseline") == method for result in methods.values()):
        return None
    baseline = methods[method].get("baseline", default)
    return baseline if baseline in methods else None


def _compare_with(
    methods: dict[str, Any],
    runs: Sequence[dict[str, Any]],
    sources: int | None,
    baseline: str,
    default: str,
    seed: int,
    reps: int,
    subset: str | None = None,
) -> dict[str, Any]:
    """
    :func:`compare` of ``runs`` (whose seeds read ``sources`` distinct sources) with every run of ``baseline`` (named
    in the verdict unless it is ``default``).
    """
    against = None if baseline == default else baseline
    shared = shared_sources(sources, methods[baseline].get("sources"))
    comparison = compare(runs, methods[baseline]["runs"], seed, reps, subset=subset, against=against, sources=shared)
    return {**comparison, "baseline": baseline}


#: How the seeds of a subset row were chosen (:func:`source_split_statistics`), in its verdict.
SOURCE_LEARNED_SUBSET = "the seeds whose source learned"


def source_split_statistics(summary: dict[str, Any], baseline: str, seed: int = 0, reps: int = REPS) -> dict[str, Any]:
    """
    The statistics of the methods that read a trained source (``summary["source"]["methods"]``) over the seeds whose
    source learned its own task (``learned`` in ``summary["source"]["runs"]``), each compared with its baseline
    (:func:`summary_statistics`'s) over all of the baseline's seeds: it reads no source, so no seed of it is left
    out. Computed only where those seeds are some but not all of the seeds whose source was recorded (else the rows
    would be none, or the headline's again).

    :param summary: the summary, with its ``source``
    :param baseline: the method the others are compared with
    :param seed: the bootstrap's random seed
    :param reps: bootstrap replications
    :return: ``learned_at`` (the source's final success from which it learned), ``seeds`` (those whose source
        learned), ``of`` (those whose source was recorded), ``not_recorded`` (the summary's other seeds), and
        ``methods`` / ``comparisons`` as :func:`summary_statistics`'s (a method's ``sources``: the subset's distinct
        sources), empty where the subset is none or every seed; each verdict at most "a hint"
    """
    source, methods = summary["source"], summary["methods"]
    learned = [run["seed"] for run in source["runs"] if run["learned"]]
    recorded = [run["seed"] for run in source["runs"]]
    split: dict[str, Any] = {
        "learned_at": source["learned_at"],
        "seeds": learned,
        "of": recorded,
        "not_recorded": [seed for seed in summary.get("seeds", recorded) if seed not in recorded],
        "methods": {},
        "comparisons": {},
    }
    if not 0 < len(learned) < len(recorded):
        return split
    hashes = {run["config_hash"] for run in source["runs"] if run["learned"]}
    for method in source["methods"]:
        runs = [run for run in methods[method]["runs"] if run["seed"] in learned]
        split["methods"][method] = {**method_statistics(runs, seed, reps), "sources": len(hashes)}
        against = _baseline_of(methods, method, baseline)
        if against is not None:
            split["comparisons"][method] = _compare_with(
                methods, runs, len(hashes), against, baseline, seed, reps, SOURCE_LEARNED_SUBSET
            )
    return split


def pointwise_iqm(curves: np.ndarray, seed: int = 0, reps: int = REPS) -> tuple[np.ndarray, np.ndarray]:
    """
    IQM over seeds of the success rate at each evaluation, and its stratified-bootstrap interval (for the plots).

    :param curves: success rates, shape (seeds, evaluations)
    :param seed: the bootstrap's random seed
    :param reps: bootstrap replications
    :return: the IQM (evaluations,) and the interval (2, evaluations)
    """

    def column_iqms(scores: np.ndarray) -> np.ndarray:
        return np.array([iqm(scores[:, column]) for column in range(scores.shape[1])])

    return _estimates(np.asarray(curves, dtype=np.float64), column_iqms, seed, reps)
