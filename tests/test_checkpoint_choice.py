"""
The controller's checkpoint chosen inside a challenge (:class:`ChooseCheckpoint`): the rule, the checkpoints a zoo run
keeps, the held-out episodes of the controller's own task, the chosen model copied where the guided stages read it, and
bad input. On hand-made zoo runs of tiny models on ``Pilot/Maze2D-v0`` (seconds).
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import gymnasium as gym
import pytest
import yaml
from stable_baselines3 import SAC
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from sb3_pilot.envs.maze import WallMarginWrapper
from sb3_pilot.experiments.challenges import BUDGETS, CHALLENGES, REUSE_SHIPPED, Shipped, ZooTrain
from sb3_pilot.experiments.challenges.controller import (
    CHOICE_SEED,
    ChooseCheckpoint,
    ControllerEvaluation,
    choose_checkpoint,
    find_checkpoints,
)
from sb3_pilot.experiments.challenges.stages import StageContext
from sb3_pilot.experiments.zoo_run import load_zoo_model, training_task

ENV_ID, ENV_NAME = "Pilot/Maze2D-v0", "Pilot-Maze2D-v0"


def zoo_run(seed_dir: Path, steps: list[int], final_steps: int, normalize: bool = False) -> Path:
    """
    A zoo run folder as ``--save-freq`` leaves it: a checkpoint at each of ``steps`` (a model of its own each), the
    final model and its saved settings (the YAML's options and wrapper, the command line).

    :return: the final model's path
    """
    run_dir = seed_dir / "controller" / "sac" / f"{ENV_NAME}_1"
    saved = run_dir / ENV_NAME
    saved.mkdir(parents=True)
    (saved / "args.yml").write_text(yaml.dump({"algo": "sac", "env": ENV_ID, "env_kwargs": None}))
    config = {
        "env_kwargs": {"max_episode_steps": 40},
        "env_wrapper": [{"sb3_pilot.envs.maze.WallMarginWrapper": {"margin": 0.5}}],
    }
    (saved / "config.yml").write_text(yaml.dump({**config, "normalize": normalize}))
    for seed, (name, at) in enumerate([*((f"rl_model_{n}_steps", n) for n in steps), (ENV_NAME, final_steps)]):
        model = SAC("MultiInputPolicy", gym.make(ENV_ID), buffer_size=10, policy_kwargs={"net_arch": [8]}, seed=seed)
        model.num_timesteps = at
        model.save(run_dir / f"{name}.zip")
        if normalize:
            stats = VecNormalize(DummyVecEnv([lambda: gym.make(ENV_ID)]), norm_reward=False)
            stats.save(
                str(saved / "vecnormalize.pkl" if name == ENV_NAME else run_dir / f"rl_model_vecnormalize_{at}_steps.pkl")
            )
    return run_dir / f"{ENV_NAME}.zip"


def context(seed_dir: Path, final: Path) -> StageContext:
    """The smoke budget's context: 2 episodes of 20 steps per checkpoint."""
    ctx = StageContext(seed_dir, 0, BUDGETS["smoke"], steps={"chosen": 20})
    ctx.outputs = {"controller": final}
    return ctx


def test_the_rule() -> None:
    """Success first; equal success goes to the lower mean final distance, then to the fewer steps."""

    def score(steps: int, success: float, distance: float) -> dict[str, Any]:
        return {"steps": steps, "success": success, "final_distance": distance}

    assert choose_checkpoint([score(1, 0.5, 0.1), score(2, 0.6, 9.0), score(3, 0.4, 0.0)])["steps"] == 2
    assert choose_checkpoint([score(1, 0.6, 2.0), score(2, 0.6, 1.0), score(3, 0.5, 0.0)])["steps"] == 2
    assert choose_checkpoint([score(3, 0.6, 1.0), score(2, 0.6, 1.0)])["steps"] == 2
    with pytest.raises(ValueError, match="No checkpoint"):
        choose_checkpoint([])


def test_checkpoints_found_with_the_final_model(tmp_path: Path) -> None:
    final = zoo_run(tmp_path, [10, 20, 30], final_steps=30)
    found = find_checkpoints(final.parent)
    assert list(found) == [10, 20, 30] and found[30].name == "rl_model_30_steps.zip"  # the same model as the final
    final = zoo_run(tmp_path / "longer", [10], final_steps=15)
    assert find_checkpoints(final.parent) == {10: final.parent / "rl_model_10_steps.zip", 15: final}


def test_no_checkpoint_names_the_folder(tmp_path: Path) -> None:
    final = zoo_run(tmp_path, [], final_steps=30)
    with pytest.raises(FileNotFoundError, match=rf"No checkpoint .* in {re.escape(str(final.parent))}: .*checkpoints=N"):
        ChooseCheckpoint("chosen", "controller").run(context(tmp_path, final), tmp_path / "chosen")
    assert not (tmp_path / "chosen").exists()  # before any episode


def test_training_task_as_saved(tmp_path: Path) -> None:
    final = zoo_run(tmp_path, [10], final_steps=10)
    env = training_task(final, max_episode_steps=7)
    assert isinstance(env, WallMarginWrapper) and env.margin == 0.5
    assert env.spec is not None and env.spec.id == ENV_ID and env.spec.max_episode_steps == 7
    assert training_task(final).spec.max_episode_steps == 40  # the saved env_kwargs'


def test_choice_scored_on_held_out_episodes_and_copied(tmp_path: Path) -> None:
    final = zoo_run(tmp_path, [10, 20], final_steps=30)
    stage = ChooseCheckpoint("chosen", "controller")
    ctx = context(tmp_path, final)
    stage_dir = tmp_path / "chosen"
    stage.run(ctx, stage_dir)
    choice = json.loads((stage_dir / "choice.json").read_text())
    assert [score["steps"] for score in choice["checkpoints"]] == [10, 20, 30]
    assert choice["seed"] == CHOICE_SEED and choice["episodes"] == 2
    for score in choice["checkpoints"]:
        assert len(score["successes"]) == len(score["final_distances"]) == 2
        assert score["final_distance"] == pytest.approx(sum(score["final_distances"]) / 2)
    best = choose_checkpoint(choice["checkpoints"])
    assert choice["chosen"] == {"steps": best["steps"], "model": best["model"]}
    assert (stage_dir / "controller.zip").read_bytes() == (tmp_path / best["model"]).read_bytes()
    model, vec_normalize = load_zoo_model(stage.output(stage_dir))  # its algorithm from the copied args.yml
    assert isinstance(model, SAC) and vec_normalize is None
    assert stage.config(ctx, stage_dir)["seed"] == CHOICE_SEED  # episodes no test episode (seed 0) uses


def test_the_chosen_file_is_the_best_scored(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """With scores set by hand, the copied model (and its statistics, in a normalised run) is the rule's choice."""
    final = zoo_run(tmp_path, [10, 20], final_steps=30, normalize=True)
    scores = {10: (0.5, 1.0), 20: (0.5, 0.5), 30: (0.0, 0.1)}

    def fake(self: ChooseCheckpoint, path: Path, stats: Path | None, env: gym.Env, ctx: StageContext) -> dict[str, Any]:
        assert stats is not None and stats.is_file()
        success, distance = scores[int(path.stem.split("_")[2]) if path != final else 30]
        return {"success": success, "final_distance": distance}

    monkeypatch.setattr(ChooseCheckpoint, "score", fake)
    stage_dir = tmp_path / "chosen"
    ChooseCheckpoint("chosen", "controller").run(context(tmp_path, final), stage_dir)
    assert json.loads((stage_dir / "choice.json").read_text())["chosen"]["steps"] == 20
    assert (stage_dir / "controller.zip").read_bytes() == (final.parent / "rl_model_20_steps.zip").read_bytes()
    stats = (stage_dir / "controller" / "vecnormalize.pkl").read_bytes()
    assert stats == (final.parent / "rl_model_vecnormalize_20_steps.pkl").read_bytes()
    assert {path.name for path in (stage_dir / "controller").iterdir()} == {"args.yml", "config.yml", "vecnormalize.pkl"}


def test_a_normalised_run_needs_each_checkpoints_statistics(tmp_path: Path) -> None:
    final = zoo_run(tmp_path, [10, 20], final_steps=30, normalize=True)
    (final.parent / "rl_model_vecnormalize_10_steps.pkl").unlink()
    with pytest.raises(FileNotFoundError, match=r"rl_model_vecnormalize_10_steps\.pkl"):
        ChooseCheckpoint("chosen", "controller").run(context(tmp_path, final), tmp_path / "chosen")


def test_controller_keeps_checkpoints_only_when_asked(tmp_path: Path) -> None:
    """``checkpoints=N`` adds the zoo's --save-freq (steps // N); without it the command, and so the hash, is as before."""
    ctx = StageContext(tmp_path, 0, BUDGETS["smoke"], steps={"a": 700})
    kept = ZooTrain("a", "sac", ENV_ID, "sac.yml", checkpoints=7).zoo_args(ctx, tmp_path)
    assert kept[kept.index("--save-freq") + 1] == "100"
    assert "--save-freq" not in ZooTrain("a", "sac", ENV_ID, "sac.yml").zoo_args(ctx, tmp_path)
    with pytest.raises(ValueError, match="a: checkpoints must be >= 0"):
        ZooTrain("a", "sac", ENV_ID, "sac.yml", checkpoints=-1)
    with pytest.raises(ValueError, match="chosen: episodes must be >= 1"):
        ChooseCheckpoint("chosen", "controller", episodes=0)


@pytest.mark.parametrize("name", ["zero-shot-ant-maze", "pointmaze-to-antmaze"])
def test_challenges_evaluate_the_chosen_checkpoint(name: str) -> None:
    stages = {stage.name: stage for stage in CHALLENGES[name].stages}
    assert isinstance(stages["controller"], ZooTrain) and stages["controller"].checkpoints > 0
    assert stages["chosen"] == ChooseCheckpoint("chosen", "controller", episodes=30)
    evaluations = [stage for stage in stages.values() if isinstance(stage, ControllerEvaluation)]
    assert evaluations and all(stage.controller == "chosen" for stage in evaluations)
    # the shipped variant evaluates its shipped controller (zero-shot-ant-maze's chosen by hand on open ground,
    # pointmaze-to-antmaze's by this stage of one training seed): no checkpoint is chosen there
    shipped = REUSE_SHIPPED[name].stages
    assert not any(isinstance(stage, ChooseCheckpoint) for stage in shipped)
    assert all(isinstance(stage, Shipped) for stage in shipped if stage.name in {"controller", "chosen"})
