"""
RL-Zoo entry point: ``python -m sb3_pilot.zoo train|enjoy|plot_train|plot_from_file|all_plots [zoo flags]``.

:func:`register` adds UDPO to the zoo as ``udpo`` (``rl_zoo3.ALGOS``, plus a hyperparameter sampler for
``--optimize``) and registers the ``Pilot/`` tasks; :func:`main` then runs the zoo's own command, as the RL-Zoo
docs do for SBX, so every zoo flag works. Three conveniences on top of ``python -m rl_zoo3.cli``:

- ``train`` without ``--conf-file`` reads this package's ``hyperparams/<algo>.yml`` for ``udpo`` and for any
  ``Pilot/`` task (the zoo would look for it inside the ``rl_zoo3`` package);
- a ``--conf-file`` that is no file from the current folder is looked up in that ``hyperparams/`` folder, so
  ``--conf-file cpu/udpo.yml`` or ``--conf-file sac_pilot.yml`` work from anywhere;
- ``plot_train -o FILE`` saves the figure (the zoo only calls ``plt.show()``), and ``-e Pilot/...`` finds the
  zoo's log folders (named ``Pilot-...``).
"""

from __future__ import annotations

import argparse
import site
import sys
import sysconfig
from pathlib import Path
from typing import Any

import gymnasium as gym
import optuna
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.save_util import load_from_zip_file

from sb3_pilot.envs import register_envs
from sb3_pilot.planner import GoalPlanner
from sb3_pilot.transfer import copy_normalization_statistics, load_vec_normalize, observation_space_mismatch
from sb3_pilot.udpo import UDPO
from sb3_pilot.wrappers import PilotBonusWrapper

#: Commands of ``python -m rl_zoo3.cli`` that :func:`main` runs.
ZOO_COMMANDS = ("train", "enjoy", "plot_train", "plot_from_file", "all_plots")
#: The paper's UDPO search grid (appendix, "Important Hyperparameters"): ``lambda`` and ``Delta``.
PLANNER_COEF_GRID = (1e-3, 5e-3, 1e-2, 5e-2, 1e-1)
INVERSE_DYNAMICS_INTERVAL_GRID = (200, 500, 1500, 2000)


def hyperparams_dir() -> Path:
    """
    The package's RL-Zoo YAML folder: ``hyperparams/`` of the source checkout (editable install), else the copy a
    wheel installs under ``<prefix>/share/sb3_pilot/hyperparams`` (setup.cfg ``data_files``).
    """
    share = Path("share", "sb3_pilot", "hyperparams")
    candidates = [
        Path(__file__).resolve().parent.parent / "hyperparams",
        Path(sysconfig.get_path("data")) / share,
        Path(site.getuserbase()) / share,
    ]
    for candidate in candidates:
        if (candidate / "udpo.yml").is_file():
            return candidate
    raise FileNotFoundError(f"sb3_pilot's hyperparams/ folder was not found in {[str(path) for path in candidates]}.")


def sample_udpo_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict[str, Any]) -> dict[str, Any]:
    """``--optimize`` sampler for UDPO: the zoo's SAC sampler plus the paper's grid for ``lambda`` and ``Delta``."""
    from rl_zoo3.hyperparams_opt import sample_sac_params

    hyperparams = sample_sac_params(trial, n_actions, n_envs, additional_args)
    hyperparams["planner_coef"] = trial.suggest_categorical("planner_coef", PLANNER_COEF_GRID)
    hyperparams["inverse_dynamics_interval"] = trial.suggest_categorical(
        "inverse_dynamics_interval", INVERSE_DYNAMICS_INTERVAL_GRID
    )
    return hyperparams


def register() -> None:
    """Register the ``Pilot/`` tasks, and UDPO as the zoo's ``udpo`` (model class, ``--optimize`` sampler)."""
    from rl_zoo3 import ALGOS
    from rl_zoo3.hyperparams_opt import HYPERPARAMS_CONVERTER, HYPERPARAMS_SAMPLER, convert_offpolicy_params

    register_envs()
    ALGOS["udpo"] = UDPO
    HYPERPARAMS_SAMPLER["udpo"] = sample_udpo_params
    HYPERPARAMS_CONVERTER["udpo"] = convert_offpolicy_params


def pilot_bonus_wrapper(env: gym.Env, planner: str, **kwargs: Any) -> PilotBonusWrapper:
    """
    ``env_wrapper`` for the zoo's YAML: :class:`~sb3_pilot.wrappers.PilotBonusWrapper` around ``env`` with the goal
    planner saved at ``planner`` (:meth:`~sb3_pilot.GoalPlanner.save`), e.g.
    ``env_wrapper: [{sb3_pilot.zoo.pilot_bonus_wrapper: {planner: planners/Pilot-Reacher-v0.pt, beta: 1.0}}]``.

    :param env: the goal env
    :param planner: path of the saved goal planner
    :param kwargs: other arguments of ``PilotBonusWrapper`` (``beta``, ``similarity``)
    """
    return PilotBonusWrapper(env, GoalPlanner.load(planner), **kwargs)


class StatePlannerTransfer(BaseCallback):
    """
    Zoo hook of the High-Dim-Action transfer (paper section 3.3): when training starts, copy the state planner of a
    source UDPO into the model being trained, frozen by default, so that only the inverse dynamics (and the critics)
    learn on the target. YAML (a zoo ``callback`` with keyword arguments)::

        callback:
          - sb3_pilot.zoo.StatePlannerTransfer:
              source: logs/udpo/Pilot-FetchReach-v0_1/Pilot-FetchReach-v0.zip

    The planner must see states scaled as it was trained: if the source was trained with ``normalize`` (the zoo
    saves its statistics as ``<log folder>/udpo/<env>_<id>/<env>/vecnormalize.pkl``, next to the zip), the target
    must be too, and its ``VecNormalize`` gets the source's statistics (``obs_rms`` and ``ret_rms``, deep copies;
    its spaces stay the target's), frozen (``training=False``) when the planner is; the zoo's evaluation env copies
    them from there. A source without ``normalize`` needs a target without it. Continuing a run with ``-i`` copies
    the source planner (and statistics) again.

    :param source: the source model's zip (the zoo saves it as ``<log folder>/udpo/<env>_<id>/<env>.zip``)
    :param freeze: keep the planner, and the observation statistics it reads, fixed on the target
    :param source_vec_normalize: the source's ``vecnormalize.pkl``, if not where the zoo saves it next to ``source``
    :param verbose: 1 prints what was copied
    """

    def __init__(self, source: str, freeze: bool = True, source_vec_normalize: str | None = None, verbose: int = 0):
        super().__init__(verbose)
        self.source = source
        self.freeze = freeze
        self.source_vec_normalize = source_vec_normalize

    def _source_stats(self) -> Path | None:
        """The source's saved ``VecNormalize`` (None: it was trained without ``normalize``)."""
        if self.source_vec_normalize is not None:
            if not Path(self.source_vec_normalize).is_file():
                raise FileNotFoundError(f"source_vec_normalize {self.source_vec_normalize} is no file.")
            return Path(self.source_vec_normalize)
        source_path = Path(self.source)
        stats = source_path.parent / source_path.stem / "vecnormalize.pkl"  # where the zoo saves them
        return stats if stats.is_file() else None

    def _on_training_start(self) -> None:
        if not isinstance(self.model, UDPO):
            raise ValueError(f"StatePlannerTransfer needs a UDPO model (it holds a state planner), got {type(self.model)}.")
        source_stats, target_norm = self._source_stats(), self.model.get_vec_normalize_env()
        if (source_stats is None) != (target_norm is None):
            used, unused = ("source", "target") if source_stats is not None else ("target", "source")
            raise ValueError(
                f"StatePlannerTransfer: the {used} uses VecNormalize (`normalize`) and the {unused} does not, so the "
                "transferred planner would see states scaled otherwise than it was trained on: train both with "
                "`normalize` (the source's statistics are then carried over) or both without."
            )
        # The policy's weights only: loading the whole source model would need its env (HER's buffer)
        source_path = Path(self.source)
        data, params, _ = load_from_zip_file(source_path, device=self.model.device)
        mismatch = observation_space_mismatch(data["observation_space"], self.model.observation_space)
        if mismatch is not None:
            raise ValueError(f"The source's state planner ({self.source}) cannot read the target's observations: {mismatch}.")
        prefix = "state_planner."
        source_state = {name[len(prefix) :]: value for name, value in params["policy"].items() if name.startswith(prefix)}
        target_planner = self.model.policy.state_planner
        source_shapes = {name: tuple(value.shape) for name, value in source_state.items()}
        target_shapes = {name: tuple(value.shape) for name, value in target_planner.state_dict().items()}
        if source_shapes != target_shapes:
            raise ValueError(
                f"The source's state planner ({self.source}) has another architecture than the target's: keep the "
                f"source's policy_kwargs (source {source_shapes}, target {target_shapes})."
            )
        if source_stats is not None and target_norm is not None:
            copy_normalization_statistics(load_vec_normalize(source_stats), target_norm, training=not self.freeze)
        target_planner.load_state_dict(source_state)
        if self.freeze:
            self.model.freeze_planner = True
            target_planner.requires_grad_(False)
        if self.verbose > 0:
            stats = f", VecNormalize statistics from {source_stats}" if source_stats is not None else ""
            print(f"State planner copied from {self.source} ({'frozen' if self.freeze else 'trainable'}){stats}")

    def _on_step(self) -> bool:
        return True


def _with_conf_file(argv: list[str]) -> list[str]:
    """``train`` arguments with ``--conf-file`` defaulted or resolved in :func:`hyperparams_dir` (see module doc)."""
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--algo", default="ppo")
    parser.add_argument("--env", default="")
    parser.add_argument("-conf", "--conf-file", default=None)
    args, _ = parser.parse_known_args(argv)
    if args.conf_file is None:
        default = hyperparams_dir() / f"{args.algo}.yml"
        if default.is_file() and (args.algo == "udpo" or args.env.startswith("Pilot/")):
            return [*argv, "--conf-file", str(default)]
    elif not Path(args.conf_file).exists() and (hyperparams_dir() / args.conf_file).is_file():
        return [*argv, "--conf-file", str(hyperparams_dir() / args.conf_file)]
    return argv


def _plot_train(argv: list[str], prog: str) -> None:
    """The zoo's ``plot_train``, with ``-o/--output`` (save the figure) and ``Pilot/`` env IDs."""
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("-o", "--output", default=None)
    args, zoo_argv = parser.parse_known_args(argv)
    if args.output is not None:
        import matplotlib

        matplotlib.use("Agg")  # the zoo's plt.show() does nothing and the figure stays open to be saved
    from matplotlib import pyplot as plt
    from rl_zoo3.plots import plot_train

    sys.argv = [prog, *(arg.replace("/", "-") if arg in gym.registry else arg for arg in zoo_argv)]
    plot_train()
    if args.output is not None:
        plt.savefig(args.output)
        print(f"Saved {args.output}")


def main(argv: list[str] | None = None) -> None:
    """Run ``python -m sb3_pilot.zoo COMMAND [zoo flags]`` (``argv`` defaults to ``sys.argv[1:]``)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] not in ZOO_COMMANDS:
        raise SystemExit(f"usage: python -m sb3_pilot.zoo {{{','.join(ZOO_COMMANDS)}}} [RL-Zoo flags, see COMMAND -h]")
    command, zoo_argv = argv[0], argv[1:]
    prog = f"python -m sb3_pilot.zoo {command}"
    register()
    if command == "train":
        from rl_zoo3.train import train

        sys.argv = [prog, *_with_conf_file(zoo_argv)]
        train()
    elif command == "enjoy":
        from rl_zoo3.enjoy import enjoy

        sys.argv = [prog, *zoo_argv]
        enjoy()
    elif command == "plot_train":
        _plot_train(zoo_argv, prog)
    else:
        from rl_zoo3 import plots

        sys.argv = [prog, *zoo_argv]
        getattr(plots, command)()


if __name__ == "__main__":
    main()
