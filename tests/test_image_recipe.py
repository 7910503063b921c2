"""benchmarks.image_recipe: the variants' zoo arguments, resumption, the time limit, the table, bad input (the zoo stubbed)."""

from __future__ import annotations

import argparse
import json
import shlex
import signal
import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml
from rl_zoo3.utils import StoreDict

from benchmarks import image_localisation, image_probe, image_recipe
from sb3_pilot.common.wrappers import ImageFrameStack
from sb3_pilot.experiments.statistics import iqm
from sb3_pilot.experiments.zoo_run import load_zoo_model
from sb3_pilot.sac import LeanSAC

TASK = "Pilot/ReacherImage-v0"
#: A stand-in for ``python -m sb3_pilot.experiments.zoo train``: the zoo's evaluations.npz at each --eval-freq up to -n,
#: success rising with the step (faster for show_target:False), FAKE_ZOO_SLEEP seconds after each evaluation, exit 0 on
#: SIGINT (as the zoo saves and exits); with --checkpoint-freq a checkpoint at each evaluation, with --resume going on
#: after the evaluations there.
FAKE_ZOO = textwrap.dedent(
    """
    import os, sys, time
    from pathlib import Path
    import numpy as np

    args = sys.argv[2:]
    value = lambda flag: args[args.index(flag) + 1]
    steps, every, episodes = int(value("-n")), int(value("--eval-freq")), int(value("--eval-episodes"))
    folder = Path("sac", value("--env").replace("/", "-") + "_1")
    resume = "--resume" in args
    folder.mkdir(parents=True, exist_ok=resume)
    pace = 2 if "show_target:False" in args else 1
    done = np.load(folder / "evaluations.npz")["timesteps"].tolist() if resume else []
    if resume:
        Path("resumed").touch()
    try:
        for step in range(every, steps + 1, every):
            if step in done:
                continue
            done.append(step)
            rates = np.minimum(1.0, pace * np.array(done) / steps)
            successes = (np.arange(episodes) < np.round(rates[:, None] * episodes)).astype(float)
            final_distances = 0.2 * (1 - successes.mean(axis=1))
            np.savez(folder / "evaluations", timesteps=done, successes=successes, final_distances=final_distances)
            if "--checkpoint-freq" in args:
                (folder / "checkpoint").mkdir(exist_ok=True)
                (folder / "checkpoint" / "checkpoint.json").write_text("{}")
            time.sleep(float(os.environ.get("FAKE_ZOO_SLEEP", "0")))
    except KeyboardInterrupt:
        Path("saved").touch()  # as the zoo saves its model on Ctrl-C
    """
)


@pytest.fixture()
def fake_zoo(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    script = tmp_path / "fake_zoo.py"
    script.write_text(FAKE_ZOO)
    monkeypatch.setattr(image_recipe, "ZOO", (str(script),))
    return script


def recipe(root: Path, *extra: str) -> list[str]:
    return ["--task", TASK, "--steps", "400", "--eval-freq", "200", "--eval-episodes", "4", "--root", str(root), *extra]


def test_variant_args_as_the_zoo_reads_them() -> None:
    entry = image_recipe.preset_entry(TASK)
    assert image_recipe.variant_args(entry, image_recipe.parse_variant("drawn")) == []
    args = image_recipe.variant_args(entry, image_recipe.parse_variant("hidden+noshift+stack3"))
    parser = argparse.ArgumentParser()
    parser.add_argument("--env-kwargs", nargs="+", action=StoreDict)
    parser.add_argument("-params", "--hyperparams", nargs="+", action=StoreDict)
    parsed = parser.parse_args(args)
    assert parsed.env_kwargs == {"show_target": False}
    preset_kwargs = eval(entry["policy_kwargs"])["features_extractor_kwargs"]
    assert preset_kwargs["random_shift"] == 4
    assert parsed.hyperparams["policy_kwargs"] == {"features_extractor_kwargs": {**preset_kwargs, "random_shift": 0}}
    assert parsed.hyperparams["env_wrapper"] == [{image_recipe.FRAME_STACK: {"n_frames": 3}}]
    # the zoo evaluates a string normalize into VecNormalize's kwargs: the goal entries only
    parsed = parser.parse_args(image_recipe.variant_args(entry, image_recipe.parse_variant("hidden+goalnorm")))
    assert eval(parsed.hyperparams["normalize"]) == {"norm_obs_keys": ["achieved_goal", "desired_goal"], "norm_reward": False}
    assert parsed.hyperparams["vec_env_wrapper"] == "stable_baselines3.common.vec_env.VecTransposeImage"
    # zoorl: the vector sources' RL settings as hyperparameters
    parsed = parser.parse_args(image_recipe.variant_args(entry, image_recipe.parse_variant("zoorl")))
    assert parsed.hyperparams == {
        "gamma": 0.95,
        "learning_rate": 1e-3,
        "learning_starts": 1000,
        "n_envs": 1,
        "train_freq": 1,
        "gradient_steps": 1,
    }
    # goalpred: the preset's policy kwargs plus the loss's weight, under the package's SAC
    changes = image_recipe.parse_variant("goalpred+noshift")
    assert changes.algo == "lean_sac"
    parsed = parser.parse_args(image_recipe.variant_args(entry, changes))
    assert parsed.hyperparams["policy_kwargs"] == {
        "features_extractor_kwargs": {**preset_kwargs, "random_shift": 0},
        "goal_prediction": image_recipe.GOAL_PREDICTION,
    }
    # fast: the preset's HER settings with the buffer on the device, CUDA graphs, the package's SAC
    changes = image_recipe.parse_variant("fast")
    assert changes.algo == "lean_sac"
    parsed = parser.parse_args(image_recipe.variant_args(entry, changes))
    assert parsed.hyperparams == {
        "replay_buffer_kwargs": {**eval(entry["replay_buffer_kwargs"]), "storage": "device"},
        "cuda_graphs": True,
    }


def test_pilot_and_cheap_variants(tmp_path: Path) -> None:
    """pilot: image/sac_pilot.yml's entry with each seed's planner in its bonus wrapper; cheap: unaliased frames."""
    for seed in (0, 1):
        (tmp_path / f"planner_{seed}.pt").write_bytes(b"")
    args = ["--task", "Pilot/FetchReachImage-v0", "--variants", "hidden+cheap", "hidden+cheap+pilot", "--seeds", "0", "1"]
    args += ["--steps", "400", "--eval-freq", "200", "--root", str(tmp_path / "runs")]
    runs = image_recipe.plan_runs(image_recipe.parser().parse_args([*args, "--planner", str(tmp_path / "planner_{seed}.pt")]))
    parser = argparse.ArgumentParser()
    parser.add_argument("--env-kwargs", nargs="+", action=StoreDict)
    parser.add_argument("-params", "--hyperparams", nargs="+", action=StoreDict)
    for run in runs:
        conf_file = run.args[run.args.index("--conf-file") + 1]
        parsed = parser.parse_args(run.args[run.args.index("--env-kwargs") :])
        assert parsed.env_kwargs == {"show_target": False, "antialias": False}
        if run.variant == "hidden+cheap":
            assert conf_file == image_recipe.CONF_FILE and parsed.hyperparams is None
            continue
        assert conf_file == image_recipe.PILOT_CONF_FILE
        entry = image_recipe.preset_entry("Pilot/FetchReachImage-v0", conf_file)
        (bonus,) = entry["env_wrapper"]
        kwargs = {**bonus[image_recipe.BONUS_WRAPPER], "planner": str(tmp_path / f"planner_{run.seed}.pt")}
        assert kwargs["similarity"] == "displacement_cosine"
        assert parsed.hyperparams == {"env_wrapper": [{image_recipe.BONUS_WRAPPER: kwargs}]}
    with pytest.raises(ValueError, match="needs --planner"):
        image_recipe.plan_runs(image_recipe.parser().parse_args(args))
    missing = ["--planner", str(tmp_path / "planner_{seed}_missing.pt")]
    with pytest.raises(ValueError, match=r"no planner at .*planner_0_missing\.pt"):
        image_recipe.plan_runs(image_recipe.parser().parse_args([*args, *missing]))


def test_iqm_is_rliables() -> None:
    values = np.random.default_rng(0).uniform(size=9)
    assert image_recipe.iqm(values) == pytest.approx(iqm(values))
    assert image_recipe.iqm([0.0, 1.0]) == 0.5  # the plain mean under 4 seeds


def test_runs_resume_and_table(tmp_path: Path, fake_zoo: Path) -> None:
    root = tmp_path / "runs"
    summary = image_recipe.main(recipe(root, "--variants", "drawn", "hidden", "--seeds", "0", "1", "--jobs", "2"))
    folder = root / "hidden" / "seed_1"
    words = shlex.split((folder / "command.txt").read_text())
    assert words[:2] == ["python", str(fake_zoo)] and words[words.index("--seed") + 1] == "1"
    assert words[words.index("--env-kwargs") + 1] == "show_target:False"
    assert json.loads((folder / "status.json").read_text())["finished"]
    # drawn: success 0.5 at step 200, 1.0 at 400; hidden: twice as fast
    drawn, hidden = summary["variants"]["drawn"], summary["variants"]["hidden"]
    assert [point["success_iqm"] for point in drawn["curve"]] == [0.5, 1.0]
    assert [point["final_distance_mean"] for point in drawn["curve"]] == pytest.approx([0.1, 0.0])
    assert drawn["steps_to_50"] == {"iqm": 200.0, "reached": 2, "seeds": 2, "censored_at": 600}
    assert hidden["curve"][0]["success_mean"] == 1.0
    assert json.loads((root / "summary.json").read_text())["command"].startswith("python -m benchmarks.image_recipe --task")
    assert "| drawn | 2 (2) | 400 | 1.00 |" in (root / "summary.md").read_text()

    # one run unfinished (its last evaluation lost): only that one runs again
    evaluations = {path: path.stat().st_mtime_ns for path in root.glob("*/seed_*/sac/*/evaluations.npz")}
    unfinished = root / "drawn" / "seed_0"
    data = dict(np.load(next(unfinished.glob("sac/*/evaluations.npz"))))
    np.savez(next(unfinished.glob("sac/*/evaluations.npz")), **{key: value[:1] for key, value in data.items()})
    assert not image_recipe.is_finished(unfinished, 400)
    image_recipe.main(recipe(root, "--variants", "drawn", "hidden", "--seeds", "0", "1", "--jobs", "2"))
    changed = {path for path, mtime in evaluations.items() if path.stat().st_mtime_ns != mtime}
    assert [path.relative_to(root).parts[:2] for path in changed] == [("drawn", "seed_0")]
    assert image_recipe.is_finished(unfinished, 400)


@pytest.mark.parametrize("sigint_ignored", [False, True])
def test_time_limit_keeps_evaluations(
    tmp_path: Path, fake_zoo: Path, monkeypatch: pytest.MonkeyPatch, sigint_ignored: bool
) -> None:
    """The runs still going are interrupted and save, even under a runner started with SIGINT ignored (nohup &)."""
    monkeypatch.setenv("FAKE_ZOO_SLEEP", "60")
    root = tmp_path / "runs"
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN if sigint_ignored else signal.default_int_handler)
    try:
        summary = image_recipe.main(
            recipe(root, "--variants", "noshift", "--seeds", "0", "1", "2", "--jobs", "2", "--time-limit", "3")
        )
    finally:
        signal.signal(signal.SIGINT, previous)
    assert all((root / "noshift" / f"seed_{seed}" / "saved").exists() for seed in (0, 1))
    runs = summary["variants"]["noshift"]["runs"]
    assert [run["seed"] for run in runs] == [0, 1]  # seed 2 never started
    assert all(run["timesteps"] == [200] and not run["finished"] for run in runs)
    status = json.loads((root / "noshift" / "seed_0" / "status.json").read_text())
    assert status["stopped_by_time_limit"] and status["seconds"] < 60  # stopped before the stub's 60 s end
    assert not (root / "noshift" / "seed_2").exists()


def test_stopped_runs_resume_from_their_checkpoints(tmp_path: Path, fake_zoo: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """
    A run stopped by the time limit keeps its checkpoint; --resume continues it in its folder (not cleared) with the
    zoo's --resume, its command unchanged; an unfinished run without a checkpoint is refused before anything runs.
    """
    monkeypatch.setenv("FAKE_ZOO_SLEEP", "60")
    root = tmp_path / "runs"
    args = recipe(root, "--variants", "noshift", "--seeds", "0", "--checkpoint-freq", "200")
    image_recipe.main([*args, "--time-limit", "3"])
    folder = root / "noshift" / "seed_0"
    command = (folder / "command.txt").read_text()
    assert "--checkpoint-freq 200" in command and (folder / "saved").exists()
    monkeypatch.setenv("FAKE_ZOO_SLEEP", "0")
    (root / "noshift" / "seed_1").mkdir()  # started, no checkpoint
    with pytest.raises(SystemExit, match=r"--resume: no checkpoint in \S*seed_1 "):
        image_recipe.main(recipe(root, "--variants", "noshift", "--seeds", "0", "1", "--checkpoint-freq", "200", "--resume"))
    summary = image_recipe.main([*args, "--resume"])
    assert (folder / "resumed").exists() and (folder / "saved").exists()  # the same folder, gone on
    assert (folder / "command.txt").read_text() == command
    (run,) = summary["variants"]["noshift"]["runs"]
    assert run["timesteps"] == [200, 400] and run["finished"]


def test_table_from_evaluation_files(tmp_path: Path) -> None:
    """--report: the table of the evaluations there, IQM over 4 seeds cutting the best and the worst."""
    root = tmp_path / "runs"
    finals = [0.0, 0.4, 0.6, 1.0]
    for seed, final in enumerate(finals):
        folder = root / "stack3" / f"seed_{seed}" / "sac" / "Pilot-ReacherImage-v0_1"
        folder.mkdir(parents=True)
        successes = np.array([[0.0] * 4, [final >= 0.5] * 4, [final] * 4])
        np.savez(folder / "evaluations", timesteps=[200, 400, 600], successes=successes, final_distances=[0.3, 0.2, 0.1])
    args = recipe(root, "--variants", "stack3", "--seeds", "0", "1", "2", "3", "--report")
    args[args.index("--steps") + 1] = "600"
    summary = image_recipe.main(args)["variants"]["stack3"]
    assert summary["final_success_iqm"] == pytest.approx(0.5)  # (0.4 + 0.6) / 2
    assert summary["curve"][-1]["success_mean"] == pytest.approx(0.5)
    assert [run["steps_to_50"] for run in summary["runs"]] == [None, None, 400, 400]
    assert summary["steps_to_50"]["reached"] == 2 and summary["steps_to_50"]["iqm"] == pytest.approx((400 + 800) / 2)
    text = (root / "summary.md").read_text()
    assert "seed 0: not by 600" in text and "| stack3 | 4 (4) | 600 | 0.50 | 0.100 | 600 (2/4) | - |" in text


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--variants", "drawn", "blurred"], "Unknown variant part(s) ['blurred']"),
        (["--variants", "drawn+hidden"], "combines 'drawn'"),
        (["--task", "Pilot/Reacher-v0"], "no entry in hyperparams/image/sac.yml"),
        (["--eval-freq", "150"], "multiple of the variants' n_envs (4)"),
        (["--variants", "zoorl", "hidden", "--eval-freq", "50"], "multiple of the variants' n_envs (4)"),
        (["--eval-freq", "120"], "a multiple of --eval-freq"),
        (["--seeds", "0", "0"], "distinct"),
        (["--jobs", "0"], "--jobs"),
        (["--resume"], "--resume continues the runs from their checkpoints: give the --checkpoint-freq"),
        (["--checkpoint-freq", "-5"], "--checkpoint-freq must be >= 0"),
    ],
)
def test_bad_input(tmp_path: Path, fake_zoo: Path, args: list[str], message: str) -> None:
    root = tmp_path / "runs"
    with pytest.raises(SystemExit) as error:
        image_recipe.main([*recipe(root), *args])
    assert message in str(error.value)
    assert not root.exists()  # nothing started


def test_eval_freq_counts_each_variants_envs(tmp_path: Path) -> None:
    """zoorl runs one env: its evaluations may fall between the preset's 4-env vector steps."""
    parser_args = image_recipe.parser().parse_args(recipe(tmp_path, "--variants", "zoorl", "--eval-freq", "50"))
    runs = image_recipe.plan_runs(parser_args)
    assert {run.args[run.args.index("--eval-freq") + 1] for run in runs} == {"50"}


def test_another_command_is_refused(tmp_path: Path, fake_zoo: Path) -> None:
    root = tmp_path / "runs"
    image_recipe.main(recipe(root, "--variants", "drawn", "--seeds", "0"))
    args = recipe(root, "--variants", "drawn", "--seeds", "0", "--device", "cpu")
    image_recipe.main(args)  # the device aside, the same runs: skipped
    args[args.index("--steps") + 1] = "600"
    with pytest.raises(SystemExit, match="holds a run of another command"):
        image_recipe.main(args)


def test_goalnorm_goalpred_fast_run_trains_and_loads(tmp_path: Path) -> None:
    """
    A real zoo run of goalnorm + stack3 + goalpred + fast: its VecNormalize (goals only, over transposed stacked frames)
    saves and loads, the package's SAC trains the goal prediction, from the device-resident buffer (on CPU tensors
    here, the step eager).
    """
    image_recipe.main(recipe(tmp_path, "--variants", "hidden+goalnorm+stack3+goalpred+fast", "--seeds", "0"))
    run = tmp_path / "hidden+goalnorm+stack3+goalpred+fast" / "seed_0" / "lean_sac" / "Pilot-ReacherImage-v0_1"
    log = (run.parents[1] / "train.log").read_text()
    assert "goal_prediction_loss" in log and "the eager gradient step is used" in log
    config = yaml.unsafe_load((run / "Pilot-ReacherImage-v0" / "config.yml").read_text())
    assert dict(config)["cuda_graphs"] and dict(config)["replay_buffer_kwargs"]["storage"] == "device"
    model, vec_normalize = load_zoo_model(run / "Pilot-ReacherImage-v0.zip")
    assert isinstance(model, LeanSAC) and model.policy.goal_prediction == image_recipe.GOAL_PREDICTION
    assert vec_normalize is not None and vec_normalize.norm_obs_keys == ["achieved_goal", "desired_goal"]
    # the statistics' env is rebuilt with the run's env_wrapper: 3 stacked frames, transposed
    assert vec_normalize.observation_space["observation"].shape == (9, 64, 64)
    env = ImageFrameStack(gym.make(TASK, show_target=False), n_frames=3)
    observation, _ = env.reset(seed=0)
    normalized = vec_normalize.normalize_obs(observation)
    assert np.array_equal(normalized["observation"], observation["observation"])  # the frame untouched
    assert not np.allclose(normalized["desired_goal"], observation["desired_goal"])
    action, _ = model.predict(normalized, deterministic=True)
    assert env.action_space.contains(action)


def test_image_probe_and_localisation_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The probe's row on a real (tiny) zoo run of the lean SAC, and the supervised localisation's rows, as numbers."""
    image_recipe.main(recipe(tmp_path, "--variants", "goalpred", "--seeds", "0"))
    model_path = tmp_path / "goalpred" / "seed_0" / "lean_sac" / "Pilot-ReacherImage-v0_1" / "Pilot-ReacherImage-v0.zip"
    capsys.readouterr()
    image_probe.main([str(model_path), "--episodes", "3"])
    row = capsys.readouterr().out.strip().splitlines()[-1].split("|")[2:-1]
    frames, r2, error, untrained_r2, untrained_error, across_goals, across_frames = map(float, row)
    assert frames == 150 and r2 <= 1 and untrained_r2 <= 1 and error > 0 and untrained_error > 0
    assert across_goals >= 0 and across_frames > 0
    image_localisation.main(["--steps", "2", "--episodes", "4", "--shifts", "0", "2"])
    lines = capsys.readouterr().out.splitlines()
    rows = [line.split("|")[1:-1] for line in lines if line.startswith("| ") and "---" not in line]
    assert [int(row[0]) for row in rows[1:]] == [0, 2] and all(0 < float(row[2]) < 1 for row in rows[1:])
