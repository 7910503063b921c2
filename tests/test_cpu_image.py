"""
The ``cpu-image`` budget of ``vec-to-image`` (the verdict run of Vec-to-Image on Fetch-Reach-Image): the recipe the
sizing runs trained with, the cpu budget's sources, only the verdict's stages, other challenges refused; and a zoo stage
with resumable checkpoints, stopped mid-run, going on from its checkpoint at the next run.
"""

from __future__ import annotations

import json
import shlex
from pathlib import Path
from typing import Any

import pytest
import yaml
from stable_baselines3 import SAC

from sb3_pilot.common.saved_models import without_replay_buffer
from sb3_pilot.experiments.challenges import BUDGETS, CHALLENGES, Challenge, ZooTrain, run_challenge
from sb3_pilot.experiments.challenges.definitions import BUDGET_CHALLENGES, HER
from sb3_pilot.experiments.challenges.display import RunDisplay
from sb3_pilot.experiments.challenges.runner import context_kwargs, stage_tasks
from sb3_pilot.experiments.challenges.stages import (
    EVALUATED_KEYS,
    REPO_DIR,
    STAGE_LOG,
    STAGE_MARKER,
    StageContext,
    zoo_hyperparams,
    zoo_run_dir,
    zoo_value,
)
from sb3_pilot.experiments.zoo import hyperparams_dir

VERDICT = BUDGET_CHALLENGES["cpu-image"]["vec-to-image"]
#: The sizing runs of both arms (issue 61), whose commands the verdict's arms must repeat.
SIZING = REPO_DIR / "zoo_runs" / "fetch-image-sizing"


def _options(words: list[str]) -> dict[str, list[str]]:
    """A zoo command's options after ``train``: each flag with the words that follow it."""
    options: dict[str, list[str]] = {}
    for word in words:
        if word.startswith("-") and not word.lstrip("-")[:1].isdigit():
            flag = options.setdefault(word, [])
        else:
            flag.append(word)
    return options


def _without_planner(hyperparams: dict[str, Any]) -> dict[str, Any]:
    """The hyperparameters with the bonus wrapper's planner path (another folder in each run) left out."""
    wrappers = [
        {name: {key: value for key, value in kwargs.items() if key != "planner"} for name, kwargs in wrapper.items()}
        for wrapper in hyperparams.get("env_wrapper", [])
    ]
    return {**hyperparams, "env_wrapper": wrappers} if wrappers else hyperparams


@pytest.mark.parametrize(("stage_name", "variant"), [("her", "hidden+cheap"), ("pilot_disp", "hidden+cheap+pilot")])
def test_the_verdict_arms_train_as_the_sizing_runs_did(tmp_path: Path, stage_name: str, variant: str) -> None:
    """Each arm's zoo command at cpu-image is its sizing run's (algorithm, YAML, task options, steps, evaluations and
    every hyperparameter as the zoo merges them), with a checkpoint every 10k and the runner's CSV logger added."""
    sized = shlex.split((SIZING / variant / "seed_0" / "command.txt").read_text())
    assert sized[:4] == ["python", "-m", "sb3_pilot.experiments.zoo", "train"]
    sized_options = _options(sized[4:])
    stage = next(stage for stage in VERDICT.stages if stage.name == stage_name)
    assert isinstance(stage, ZooTrain)
    ctx = StageContext(tmp_path, 0, BUDGETS["cpu-image"], VERDICT.steps["cpu-image"], VERDICT.recipe)
    ctx.outputs = {"distill": tmp_path / "distill" / "planner.pt"}
    config = stage.config(ctx, tmp_path / stage_name)
    options = _options(config["zoo"][1:])
    # beside the sizing's options, a checkpoint every 10k (and -params: compared below, as the zoo merges them)
    assert set(sized_options) <= set(options) and set(options) - set(sized_options) <= {"--checkpoint-freq", "-params"}
    assert options["--checkpoint-freq"] == ["10000"]
    for flag in ("--algo", "--env", "--conf-file", "--seed", "-n", "--eval-freq", "--eval-episodes", "--num-threads"):
        assert options[flag] == sized_options[flag], flag
    assert options["--env-kwargs"] == sized_options["--env-kwargs"] == ["show_target:False", "antialias:False"]
    # the hyperparameters: the YAML entry with -params over it, as the zoo reads them
    entry = yaml.safe_load((hyperparams_dir() / sized_options["--conf-file"][0]).read_text())["Pilot/FetchReachImage-v0"]
    assert config["preset"] == entry
    sized_params = {key: eval(value) for key, _, value in (item.partition(":") for item in sized_options.get("-params", []))}
    sized_hyperparams = {
        key: zoo_value(value) if key in EVALUATED_KEYS else value for key, value in {**entry, **sized_params}.items()
    }
    hyperparams = zoo_hyperparams(config)
    callbacks = hyperparams.pop("callback")
    assert [next(iter(callback)) for callback in callbacks] == ["sb3_pilot.experiments.challenges.stages.CSVLogger"]
    assert _without_planner(hyperparams) == _without_planner(sized_hyperparams)
    if stage_name == "pilot_disp":  # the seed's own planner, with the sized similarity and weight
        (wrapper,) = hyperparams["env_wrapper"]
        kwargs = wrapper["sb3_pilot.PilotBonusWrapper"]
        assert kwargs == {"planner": str(ctx.outputs["distill"]), "beta": 1.0, "similarity": "displacement_cosine"}


def test_the_verdict_runs_the_cpu_sources_and_the_two_arms(tmp_path: Path) -> None:
    """At cpu-image: the cpu budget's source and planner (the same hashes: one trained at cpu serves), SAC + HER and
    HER + PILoT (displacement cosine) for 100k steps; the paper's similarity, not sized, does not run."""
    assert [stage.name for stage in VERDICT.stages] == ["source", "distill", "pilot_disp", "her"]
    assert VERDICT.steps == {"cpu-image": {"source": 8000, "pilot_disp": 100_000, "her": 100_000}}
    seeds = [0, 1]
    cpu = stage_tasks(CHALLENGES["vec-to-image"], seeds, tmp_path, context_kwargs(CHALLENGES["vec-to-image"], BUDGETS["cpu"]))
    image = stage_tasks(VERDICT, seeds, tmp_path, context_kwargs(VERDICT, BUDGETS["cpu-image"]))
    for key in ("seed_0/source", "seed_0/distill", "seed_1/source", "seed_1/distill"):
        assert image[key].digest == cpu[key].digest, key
    for key in ("seed_0/pilot_disp", "seed_0/her"):
        assert image[key].digest != cpu[key].digest, key
    plan = run_challenge("vec-to-image", "cpu-image", seeds=seeds, root=tmp_path, dry_run=True)
    assert plan["to_run"] == list(image)


def test_the_cpu_image_budget_is_vec_to_image_s_only(tmp_path: Path) -> None:
    """Another challenge, or vec-to-image without its stages at that budget, is refused before any work, with the
    budgets it runs at; an unknown budget is refused with the list."""
    with pytest.raises(ValueError, match=r"cpu-image budget runs vec-to-image only.*high-dim-action runs at smoke, cpu"):
        run_challenge("high-dim-action", "cpu-image", root=tmp_path, dry_run=True)
    with pytest.raises(ValueError, match="cpu-image budget runs vec-to-image only"):
        run_challenge(CHALLENGES["vec-to-image"], "cpu-image", root=tmp_path, dry_run=True)
    with pytest.raises(ValueError, match=r"Unknown budget 'gpu', choose one of \['smoke', 'cpu', 'cpu-image'"):
        run_challenge("vec-to-image", "gpu", root=tmp_path, dry_run=True)
    assert not (tmp_path / "vec-to-image").exists() and not (tmp_path / "high-dim-action").exists()


#: The resumed stage's env steps, checkpoints and evaluations (a checkpoint every 100 steps, the stage stopped at the
#: first that the runner sees).
STEPS, CHECKPOINT_FREQ, EVAL_FREQ = 800, 100, 200
RESUMABLE = Challenge(
    "resumable",
    "SAC + HER on Maze2D, checkpointed (a test's)",
    "Pilot/Maze2D-v0",
    (ZooTrain("her", "sac", "Pilot/Maze2D-v0", "sac.yml", method=HER, eval_freq=EVAL_FREQ, checkpoint_freq=CHECKPOINT_FREQ),),
    steps={"smoke": {"her": STEPS}},
)


def _stage_dir(root: Path) -> Path:
    return root / RESUMABLE.name / "models" / "seed_0" / "her"


def test_a_stage_with_checkpoints_resumes_where_it_stopped(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Stopped (Ctrl-C) after its first checkpoint, the stage goes on from that checkpoint at the next run, not from 0,
    and ends with an uninterrupted run's env steps, gradient steps and evaluations, its wall time counting both
    sittings; under another configuration it would start over."""
    stopped = tmp_path / "stopped"
    run_dir = zoo_run_dir(_stage_dir(stopped), "sac", "Pilot/Maze2D-v0")
    checkpoint = run_dir / "checkpoint" / "checkpoint.json"

    def interrupt(display: RunDisplay) -> None:  # the runner looks at its stages every 0.2 s: Ctrl-C once one is there
        if checkpoint.is_file():
            raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr(RunDisplay, "tick", interrupt)
        with pytest.raises(KeyboardInterrupt):
            run_challenge(RESUMABLE, "smoke", root=stopped, progress=False)
    resume_from = json.loads(checkpoint.read_text())["num_timesteps"]
    assert 0 < resume_from < STEPS and resume_from % CHECKPOINT_FREQ == 0
    assert not (_stage_dir(stopped) / STAGE_MARKER).exists()
    capsys.readouterr()

    run_challenge(RESUMABLE, "smoke", root=stopped, dry_run=True, steps={"her": STEPS + CHECKPOINT_FREQ})
    assert "resumed from" not in capsys.readouterr().out  # another configuration: starts over
    assert run_challenge(RESUMABLE, "smoke", root=stopped, dry_run=True)["to_run"] == ["seed_0/her"]
    plan = capsys.readouterr().out
    assert f"resumed from its checkpoint at {resume_from} env steps" in plan and " --resume" in plan

    summary = run_challenge(RESUMABLE, "smoke", root=stopped, progress=False)
    marker = json.loads((_stage_dir(stopped) / STAGE_MARKER).read_text())
    assert marker["resumed_from"] == summary["stages"]["seed_0/her"]["resumed_from"] == resume_from
    # its wall time: this sitting's and the first sitting's training up to the checkpoint (recorded with it)
    earlier = marker["earlier_sittings_s"]
    assert earlier == summary["stages"]["seed_0/her"]["earlier_sittings_s"] > 0 and marker["wall_time_s"] > earlier
    # the zoo loaded the checkpoint (its model, counters and buffer) before training on
    log = (_stage_dir(stopped) / STAGE_LOG).read_text()
    assert f"Resuming {run_dir} at {resume_from} env steps (of {STEPS})" in log and " --resume" in log
    # the first sitting's log and progress kept beside those of the second
    assert " --resume" not in (_stage_dir(stopped) / "stage.1.log").read_text()
    assert (_stage_dir(stopped) / "progress.1.csv").is_file() and (_stage_dir(stopped) / "progress.csv").is_file()

    whole = run_challenge(RESUMABLE, "smoke", root=tmp_path / "whole", progress=False)
    evaluated = list(range(EVAL_FREQ, STEPS + 1, EVAL_FREQ))
    (resumed_run,), (whole_run,) = (result["methods"][HER]["runs"] for result in (summary, whole))
    assert resumed_run["timesteps"] == whole_run["timesteps"] == evaluated
    assert len(resumed_run["final_distance"]) == len(evaluated)
    resumed_model, whole_model = (
        SAC.load(RESUMABLE.stages[0].output(_stage_dir(root)), custom_objects=without_replay_buffer())
        for root in (stopped, tmp_path / "whole")
    )
    assert resumed_model.num_timesteps == whole_model.num_timesteps == STEPS
    assert resumed_model._n_updates == whole_model._n_updates > 0
