"""
Evaluation that also measures how far from its goal an agent ends: at a 0.1 success radius, an Ant that walks most
of the way scores 0 success, and only the distance says whether it moves towards goals.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.vec_env import unwrap_vec_normalize


def final_distance(info: dict[str, Any]) -> float | None:
    """
    Distance between the achieved and the desired goal at the end of an episode, read from the terminal observation
    a ``VecEnv`` puts in the last step's info (raw coordinates: ``VecNormalize`` normalises it, so it is unnormalised
    by the caller when needed). None for observations without goals.

    :param info: the info dict of an episode's last step
    """
    observation = info.get("terminal_observation")
    if not isinstance(observation, dict) or not {"achieved_goal", "desired_goal"} <= observation.keys():
        return None
    difference = np.asarray(observation["achieved_goal"], dtype=np.float64) - observation["desired_goal"]
    return float(np.linalg.norm(difference))


class GoalEvalCallback(EvalCallback):
    """
    SB3's ``EvalCallback`` that also records, for goal envs, the mean distance between the achieved and the desired
    goal at the end of the evaluation episodes: logged as ``eval/final_distance`` and saved in ``evaluations.npz``
    as ``final_distances`` (one value per evaluation, beside ``successes``). Same parameters as ``EvalCallback``.
    The zoo entry's ``train`` evaluates with it (:class:`~sb3_pilot.experiments.zoo_shim.PilotExperimentManager`).

    Success and distance are recorded at the episode ends ``evaluate_policy`` counts: on an env wrapped with a
    ``Monitor``, those the ``Monitor`` records. An episode ended by a wrapper above the ``Monitor`` (the zoo applies
    ``env_wrapper`` above its own ``Monitor``) is not counted (``evaluate_policy`` reads it as an Atari life lost),
    and would make ``successes`` ragged (SB3's ``EvalCallback`` then fails to save it): such an end is left out, with
    a warning once, which names the remedy, a ``Monitor`` last in ``env_wrapper``.
    """

    def __init__(self, *args: Any, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self.evaluations_final_distance: list[float] = []
        self._episode_distances: list[float] = []
        self._warned_uncounted_end = False

    @classmethod
    def from_eval_callback(cls, callback: EvalCallback) -> GoalEvalCallback:
        """
        :param callback: an ``EvalCallback`` built by code that is not ours (the RL Zoo's ``create_callbacks``), before
            training
        :return: the same evaluation (env, episodes, frequency, paths, callbacks, ...) with the final distances recorded
        """
        return cls(
            callback.eval_env,
            callback_on_new_best=callback.callback_on_new_best,
            callback_after_eval=callback.callback,
            n_eval_episodes=callback.n_eval_episodes,
            eval_freq=callback.eval_freq,
            log_path=None if callback.log_path is None else os.path.dirname(callback.log_path),  # "<log_path>/evaluations"
            best_model_save_path=callback.best_model_save_path,
            deterministic=callback.deterministic,
            render=callback.render,
            verbose=callback.verbose,
            warn=callback.warn,
        )

    def restore_history(self, last_step: int) -> None:
        """
        Take back the evaluations of ``evaluations.npz`` up to ``last_step`` (those of a run resumed from a checkpoint
        at that step), so that the file goes on with them instead of starting anew; later ones are left out (the
        resumed run evaluates there again). Without a file, nothing.

        :param last_step: the env steps of the checkpoint
        """
        path = None if self.log_path is None else Path(f"{self.log_path}.npz")
        if path is None or not path.is_file():
            return
        with np.load(path) as data:
            keep = np.asarray(data["timesteps"]) <= last_step
            self.evaluations_timesteps = data["timesteps"][keep].tolist()
            self.evaluations_results = data["results"][keep].tolist()
            self.evaluations_length = data["ep_lengths"][keep].tolist()
            if "successes" in data:
                self.evaluations_successes = data["successes"][keep].tolist()
            if "final_distances" in data:
                self.evaluations_final_distance = data["final_distances"][keep].tolist()
        if self.evaluations_results:
            self.best_mean_reward = float(max(np.mean(results) for results in self.evaluations_results))

    def _log_success_callback(self, locals_: dict[str, Any], globals_: dict[str, Any]) -> None:
        if locals_["done"] and locals_.get("is_monitor_wrapped") and "episode" not in locals_["info"]:
            if not self._warned_uncounted_end:
                warnings.warn(
                    "An evaluation episode ended without its Monitor's record: a wrapper above the Monitor ended it "
                    "(the RL Zoo applies env_wrapper above its Monitor), and evaluate_policy does not count it as an "
                    "episode. Its success is left out. To count such ends, put stable_baselines3.common.monitor.Monitor "
                    "last in env_wrapper.",
                    stacklevel=2,
                )
                self._warned_uncounted_end = True
            return
        super()._log_success_callback(locals_, globals_)
        if locals_["done"]:
            info = dict(locals_["info"])
            vec_normalize = unwrap_vec_normalize(self.eval_env)
            if vec_normalize is not None and isinstance(info.get("terminal_observation"), dict):
                info["terminal_observation"] = vec_normalize.unnormalize_obs(info["terminal_observation"])
            distance = final_distance(info)
            if distance is not None:
                self._episode_distances.append(distance)

    def _on_step(self) -> bool:
        evaluating = self.eval_freq > 0 and self.n_calls % self.eval_freq == 0
        self._episode_distances = []
        continue_training = super()._on_step()
        if evaluating and self._episode_distances:
            mean_distance = float(np.mean(self._episode_distances))
            self.evaluations_final_distance.append(mean_distance)
            self.logger.record("eval/final_distance", mean_distance)
            if self.log_path is not None:
                data = dict(np.load(f"{self.log_path}.npz" if not self.log_path.endswith(".npz") else self.log_path))
                data["final_distances"] = np.array(self.evaluations_final_distance)
                np.savez(self.log_path, **data)
        return continue_training


def load_final_distances(evaluations: str | os.PathLike) -> np.ndarray | None:
    """The ``final_distances`` of an ``evaluations.npz`` written by :class:`GoalEvalCallback` (None if it has none)."""
    with np.load(evaluations) as data:
        return np.array(data["final_distances"]) if "final_distances" in data else None
