"""``python -m sb3_pilot.experiments.zoo distill``: the goal planner of a zoo run, any off-policy goal agent as teacher."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml
from stable_baselines3 import SAC, TD3
from stable_baselines3.common.vec_env import VecNormalize

from sb3_pilot import GoalPlanner, PilotBonusWrapper
from sb3_pilot.envs.maze import WallMarginWrapper
from sb3_pilot.experiments.zoo import main, planner_path
from sb3_pilot.experiments.zoo_run import find_zoo_run, load_zoo_run

MAZE = "Pilot/Maze2D-v0"
#: Tiny runs: 20-step episodes, 40 steps before the first update, 16-unit networks
TINY = ("learning_starts:40", "batch_size:16", "policy_kwargs:dict(net_arch=[16, 16])")
STEPS = "80"


def zoo(*args: str) -> None:
    """``python -m sb3_pilot.experiments.zoo ARGS``, in this process (the command sets ``sys.argv`` for the zoo)."""
    argv = sys.argv
    try:
        main(list(args))
    finally:
        sys.argv = argv


def train(logs: Path, algo: str, *extra: str) -> None:
    common = ("--algo", algo, "--env", MAZE, "-f", str(logs), "-n", STEPS, "--seed", "0", "--eval-freq", "-1")
    zoo("train", *common, "--num-threads", "1", "--verbose", "0", "--env-kwargs", "max_episode_steps:20", *extra)


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One tiny zoo run each of SAC (normalised, a wrapper, task options), TD3, TQC and UDPO (replay buffer saved)."""
    folder = tmp_path_factory.mktemp("zoo")
    logs = folder / "logs"
    # SAC from the package's own sac.yml, as a user trains it; the run records its wrapper and normalisation
    wrapper = f"env_wrapper:'{WallMarginWrapper.__module__}.WallMarginWrapper'"
    train(logs, "sac", "-params", *TINY, "normalize:True", wrapper)
    # TD3 and TQC: the zoo's own files have no entry for the maze
    entry = yaml.safe_load((Path(__file__).parents[1] / "hyperparams" / "sac.yml").read_text())[MAZE]
    conf = folder / "conf.yml"
    conf.write_text(
        yaml.safe_dump(
            {MAZE: {key: entry[key] for key in ("n_timesteps", "policy", "replay_buffer_class", "replay_buffer_kwargs")}}
        )
    )
    for algo in ("td3", "tqc"):
        train(logs, algo, "--conf-file", str(conf), "-params", *TINY)
    train(logs, "udpo", "--save-replay-buffer", "-params", *TINY)
    # a second run, exp id 2, the latest: a copy without the replay buffer
    shutil.copytree(logs / "udpo" / "Pilot-Maze2D-v0_1", logs / "udpo" / "Pilot-Maze2D-v0_2")
    (logs / "udpo" / "Pilot-Maze2D-v0_2" / "replay_buffer.pkl").unlink()
    return logs


def distill(logs: Path, algo: str, *extra: str) -> None:
    args = ("--algo", algo, "--env", MAZE, "-f", str(logs), "--n-samples", "300", "--gradient-steps", "10")
    zoo("distill", *args, "--allow-unsuccessful-teacher", "--distill-kwargs", "net_arch:[8]", "batch_size:16", *extra)


def test_env_rebuilt_as_enjoy_does(logs: Path) -> None:
    """The run's VecNormalize statistics (frozen), env_wrapper and task options, and the zoo's class of the model."""
    model_path = find_zoo_run(logs, "sac", MAZE)
    assert model_path == logs / "sac" / "Pilot-Maze2D-v0_1" / "Pilot-Maze2D-v0.zip"
    model, env = load_zoo_run(model_path, "sac", MAZE)
    assert isinstance(model, SAC) and model.num_timesteps == int(STEPS)
    assert isinstance(env, VecNormalize) and not env.training and env.obs_rms["observation"].count > int(STEPS)
    assert model.get_vec_normalize_env() is env
    wrapped = env.venv.envs[0]
    while not isinstance(wrapped, WallMarginWrapper):
        wrapped = wrapped.env
    assert env.get_attr("spec")[0].max_episode_steps == 20
    # options over the run's own (zoo distill --env-kwargs: the rollouts' task)
    _, env = load_zoo_run(model_path, "sac", MAZE, env_kwargs={"max_episode_steps": 7})
    assert env.get_attr("spec")[0].max_episode_steps == 7 and isinstance(env, VecNormalize)
    model, env = load_zoo_run(find_zoo_run(logs, "td3", MAZE), "td3", MAZE)
    assert isinstance(model, TD3) and not isinstance(env, VecNormalize)


@pytest.mark.parametrize("algo", ["sac", "td3", "tqc", "udpo"])
def test_distill_writes_where_the_bonus_reads(logs: Path, algo: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Any off-policy goal agent of a zoo run: the planner at ``<folder>/planners/<env>.pt``, its quality printed."""
    distill(logs, algo)
    path = planner_path(logs, MAZE)
    assert path == logs / "planners" / "Pilot-Maze2D-v0.pt"
    planner = GoalPlanner.load(path)
    assert planner.source_task == MAZE and planner.metadata["labels"] == "rollouts"
    assert planner.metadata["teacher_algorithm"] == {"sac": "SAC", "td3": "TD3", "tqc": "TQC", "udpo": "UDPO"}[algo]
    exp_id = 2 if algo == "udpo" else 1  # the latest run
    assert planner.metadata["teacher_model"] == str(logs / algo / f"Pilot-Maze2D-v0_{exp_id}" / "Pilot-Maze2D-v0.zip")
    out = capsys.readouterr().out
    assert f"Saved the goal planner to {path}" in out
    assert "held-out landmark distance" in out and "the teacher's rollout success" in out and "steps at a goal" in out
    path.unlink()


def test_distill_exp_id_out_and_planned_labels(logs: Path, tmp_path: Path) -> None:
    """``--exp-id`` picks an older run, ``--out`` the file; UDPO's planned labels read the run's replay buffer."""
    out = tmp_path / "mine.pt"
    distill(logs, "udpo", "--exp-id", "1", "--labels", "planned", "--out", str(out))
    planner = GoalPlanner.load(out)
    assert planner.metadata["labels"] == "planned"
    assert planner.metadata["teacher_model"].endswith("Pilot-Maze2D-v0_1/Pilot-Maze2D-v0.zip")
    # it serves the bonus on the maze's car (one goal space)
    env = PilotBonusWrapper(gym.make("Pilot/Maze2DCar-v0"), out)
    env.reset(seed=0)
    assert np.isfinite(env.step(env.action_space.sample())[1])


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (
            ("--algo", "sac", "--env", "Pilot/Maze2DCar-v0"),
            r"No run of sac on Pilot/Maze2DCar-v0 under .*runs there: .*sac/Pilot-Maze2D-v0_1",
        ),
        (("--algo", "ddpg", "--env", MAZE), "No run of ddpg on Pilot/Maze2D-v0"),
        (
            ("--algo", "udpo", "--env", MAZE, "--exp-id", "7"),
            r"--exp-id 7: there is no run .*udpo/Pilot-Maze2D-v0_7.*\[1, 2\]",
        ),
        (("--algo", "sac", "--env", "Pilot/Nothing-v0"), "Pilot/Nothing-v0 is no registered Gymnasium task"),
        (("--algo", "sac", "--env", MAZE, "--labels", "planned"), "did not save .*--save-replay-buffer"),
        (("--algo", "sac", "--env", MAZE, "--distill-kwargs", "n_sample:3"), r"\['n_sample'\] are no arguments"),
    ],
)
def test_bad_input_named_before_work(logs: Path, args: tuple[str, ...], match: str) -> None:
    with pytest.raises(SystemExit, match=match):
        zoo("distill", *args, "-f", str(logs))
    assert not planner_path(logs, MAZE).exists()


def test_run_folder_without_model(logs: Path) -> None:
    """A run folder the zoo left without its model (an interrupted training)."""
    run = logs / "sac" / "Pilot-Maze2DCar-v0_1"
    run.mkdir(parents=True)
    try:
        with pytest.raises(SystemExit, match=r"Pilot-Maze2DCar-v0_1 has no model Pilot-Maze2DCar-v0.zip"):
            zoo("distill", "--algo", "sac", "--env", "Pilot/Maze2DCar-v0", "-f", str(logs))
    finally:
        run.rmdir()


def test_unsuccessful_teacher_refused_by_name(logs: Path) -> None:
    """A teacher whose rollouts reach no goal: refused, the message naming the command's flag to go on."""
    with pytest.raises(SystemExit, match=r"reached no goal.*--allow-unsuccessful-teacher"):
        zoo(
            "distill",
            "--algo",
            "sac",
            "--env",
            MAZE,
            "-f",
            str(logs),
            *("--n-samples", "300"),
            "--distill-kwargs",
            "batch_size:16",
        )


def test_train_distill_bonus_sequence(logs: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The guide's sequence: the planner at the default path is the one ``sac_pilot.yml``'s bonus entry reads."""
    monkeypatch.chdir(logs.parent)
    distill(Path("logs"), "sac")
    zoo(
        *("train", "--algo", "sac", "--env", "Pilot/Maze2DCar-v0", "--conf-file", "sac_pilot.yml", "-f", "logs"),
        *("-n", "30", "--eval-freq", "-1", "--num-threads", "1", "--verbose", "0", "-params", *TINY),
    )
    config = yaml.load(
        (logs / "sac" / "Pilot-Maze2DCar-v0_1" / "Pilot-Maze2DCar-v0" / "config.yml").read_text(), Loader=yaml.UnsafeLoader
    )
    (wrapper,) = dict(config)["env_wrapper"]
    assert wrapper["sb3_pilot.PilotBonusWrapper"]["planner"] == "logs/planners/Pilot-Maze2D-v0.pt"
    assert isinstance(load_zoo_run(find_zoo_run("logs", "sac", "Pilot/Maze2DCar-v0"), "sac", "Pilot/Maze2DCar-v0")[0], SAC)
    (logs / "planners" / "Pilot-Maze2D-v0.pt").unlink()


def test_unknown_labels_and_algo_refused_by_the_parser(logs: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for args, named in ((("--algo", "sac", "--labels", "real"), "'real'"), (("--algo", "ppo2"), "'ppo2'")):
        with pytest.raises(SystemExit):
            zoo("distill", *args, "--env", MAZE, "-f", str(logs))
        err = capsys.readouterr().err
        assert "invalid choice" in err and named in err
