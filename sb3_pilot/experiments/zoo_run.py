"""
A run of the RL Zoo, read back: how ``zoo distill``, the challenges' stages, the Ant controller's commands and the
pairs table find a run, read its saved settings, load its model and rebuild its env.

The zoo saves a run as ``<folder>/<algo>/<env name>_<n>/<env name>.zip`` (the final model) beside a folder
``<env name>/`` of settings (:func:`~sb3_pilot.common.saved_models.zoo_settings_dir`): ``args.yml`` (the command
line), ``config.yml`` (the YAML entry, with ``-params`` applied) and, for a normalised run, ``vecnormalize.pkl``
(:func:`~sb3_pilot.common.saved_models.vecnormalize_path`).

**The rule for** ``env_kwargs`` (:func:`env_kwargs_rule`), the zoo's own: the command line's ``--env-kwargs``, when
given, replace the YAML entry's ``env_kwargs`` whole (``rl_zoo3.exp_manager.ExperimentManager.read_hyperparameters``
when it trains; its ``enjoy`` reads a saved run so too); they are not merged key by key. A run's ``config.yml`` already
holds the replaced value when both were given, so reading a zoo-saved run by this rule or by merging the two files
gives the same task options.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import gymnasium as gym
import yaml
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecNormalize

from sb3_pilot.common.saved_models import vecnormalize_path, without_replay_buffer, zoo_settings_dir
from sb3_pilot.experiments.zoo_plugin import register


def find_zoo_run(folder: str | os.PathLike, algo: str, env_id: str, exp_id: int = 0) -> Path:
    """
    The final model of a zoo run, found as ``enjoy`` finds it: ``<folder>/<algo>/<env name>_<exp_id>/<env name>.zip``.

    :param folder: the zoo's log folder (``-f``)
    :param algo: the zoo algorithm of the run
    :param env_id: its task
    :param exp_id: the run's number (0: the latest)
    :return: the model's path
    :raises FileNotFoundError: naming what is missing: any run of ``algo`` on ``env_id`` under ``folder`` (the runs that
        are there listed), the run ``exp_id``, the run's model
    """
    from huggingface_sb3 import EnvironmentName
    from rl_zoo3.utils import get_latest_run_id

    if exp_id < 0:
        raise ValueError(f"--exp-id must be a run number (>= 1) or 0 for the latest, got {exp_id}.")
    env_name = EnvironmentName(env_id)
    algo_dir = Path(folder) / algo
    latest = get_latest_run_id(str(algo_dir), env_name)
    if latest == 0:
        runs = sorted(f"{path.parent.name}/{path.name}" for path in Path(folder).glob("*/*_[0-9]*") if path.is_dir())
        raise FileNotFoundError(
            f"No run of {algo} on {env_id} under {folder} (no folder {algo_dir / env_name}_<N>); runs there: "
            f"{', '.join(runs) or 'none'}."
        )
    run_dir = algo_dir / f"{env_name}_{exp_id or latest}"
    if not run_dir.is_dir():
        ids = sorted(int(path.name.rsplit("_", 1)[1]) for path in algo_dir.glob(f"{env_name}_[0-9]*") if path.is_dir())
        raise FileNotFoundError(f"--exp-id {exp_id}: there is no run {run_dir}; the runs of {algo} on {env_id}: {ids}.")
    model_path = run_dir / f"{env_name}.zip"
    if not model_path.is_file():
        raise FileNotFoundError(
            f"The run {run_dir} has no model {model_path.name} (the zoo saves it when training ends: was it interrupted?)."
        )
    return model_path


def zoo_saved(model_path: str | os.PathLike, name: str) -> dict[str, Any]:
    """
    A settings file the zoo saved beside a model (``args.yml``: the command line; ``config.yml``: the YAML entry).

    :param model_path: ``<run folder>/<env name>.zip``
    :param name: the file's name
    :return: its entries, empty if the file is not there (a model saved without them)
    """
    path = zoo_settings_dir(model_path) / name
    if not path.is_file():
        return {}
    # the zoo writes OrderedDicts (python tags), read back as its own enjoy script does
    return dict(yaml.load(path.read_text(), Loader=yaml.UnsafeLoader))


def zoo_algo(model_path: Path) -> str:
    """
    The zoo algorithm of a model: as its run's ``args.yml`` records it (a model copied with its saved settings, e.g. a
    chosen checkpoint), else the name of the run folder's parent (``<algo>/<env name>_<n>/<env name>.zip``).
    """
    return str(zoo_saved(model_path, "args.yml").get("algo") or model_path.parent.parent.name)


def zoo_env_id(model_path: Path) -> str:
    """
    The task of a zoo run's model: as the run's ``args.yml`` records it (any Gymnasium ID), else ``Pilot/X-v0`` from
    the zoo's ``.../Pilot-X-v0.zip`` (a shipped model).
    """
    return str(zoo_saved(model_path, "args.yml").get("env") or model_path.stem.replace("-", "/", 1))


def env_kwargs_rule(yaml_env_kwargs: dict[str, Any] | None, command_line_env_kwargs: dict[str, Any] | None) -> dict[str, Any]:
    """
    The task options of a zoo run, by the zoo's rule (see the module's doc): the command line's ``--env-kwargs``,
    when given, replace the YAML entry's ``env_kwargs`` whole.

    :param yaml_env_kwargs: the YAML entry's ``env_kwargs`` (None: it has none)
    :param command_line_env_kwargs: the command line's ``--env-kwargs`` (None or empty: not given)
    :return: a new dict
    """
    return dict(command_line_env_kwargs or yaml_env_kwargs or {})


def zoo_env_kwargs(model_path: Path) -> dict[str, Any]:
    """
    The task options a zoo run trained with, by :func:`env_kwargs_rule`: the command line's ``--env-kwargs``
    (``args.yml``) if it had some, else its YAML entry's ``env_kwargs`` (``config.yml``).

    :param model_path: ``<run folder>/<env name>.zip``
    """
    yaml_entry, command_line = zoo_saved(model_path, "config.yml"), zoo_saved(model_path, "args.yml")
    return env_kwargs_rule(yaml_entry.get("env_kwargs"), command_line.get("env_kwargs"))


#: Task options that decide what a controller sees or which body it moves: a task it is guided on must share them with
#: the task it trained on (:func:`carried_env_kwargs`): gymnasium-robotics' and gymnasium's Ant ``xml_file`` and the
#: contact forces in its observation.
CARRIED_ENV_KWARGS = ("xml_file", "include_cfrc_ext_in_observation")


def _packaged_file(path: str) -> str:
    """A MuJoCo file path as it was saved, or, where that path is not here (a run trained on another machine), the
    package's own file of that name (:data:`~sb3_pilot.envs.locomotion.ANT_XML_FILES`)."""
    from sb3_pilot.envs.locomotion import ANT_XML_FILES

    if os.path.isfile(path):
        return path
    return next((known for known in ANT_XML_FILES.values() if os.path.basename(known) == os.path.basename(path)), path)


def carried_env_kwargs(model_path: Path) -> dict[str, Any]:
    """
    The options of a zoo run's task (:func:`zoo_env_kwargs`) that a task it is guided on must share
    (:data:`CARRIED_ENV_KWARGS`), an ``xml_file`` of the package found where the run's machine had it elsewhere.

    :param model_path: ``<run folder>/<env name>.zip`` (its saved settings beside it)
    :return: those options it trained with (empty: a model without saved settings, or none of them set)
    """
    kwargs = {key: value for key, value in zoo_env_kwargs(model_path).items() if key in CARRIED_ENV_KWARGS}
    if isinstance(kwargs.get("xml_file"), str):
        kwargs["xml_file"] = _packaged_file(kwargs["xml_file"])
    return kwargs


def _accepted(env_id: str, key: str) -> bool:
    """Whether the registered task ``env_id`` takes the option ``key`` (its entry point names it or takes ``**kwargs``)."""
    import inspect

    from gymnasium.envs.registration import load_env_creator

    entry_point = gym.spec(env_id).entry_point
    creator = load_env_creator(entry_point) if isinstance(entry_point, str) else entry_point
    parameters = inspect.signature(creator).parameters
    return key in parameters or any(parameter.kind is parameter.VAR_KEYWORD for parameter in parameters.values())


def with_carried_env_kwargs(model_path: Path, env_id: str, env_kwargs: dict[str, Any]) -> dict[str, Any]:
    """
    A guided task's options with the controller's :func:`carried_env_kwargs` added where they are not given and the
    task takes them (a ``Pilot/`` Ant task names its Ant by version, not by file: the Ant's check is
    :func:`~sb3_pilot.envs.locomotion.check_same_ant`'s).

    :param model_path: the controller (a zoo run's model)
    :param env_id: the guided task (a registered Gymnasium ID)
    :param env_kwargs: its options
    :return: a new dict
    :raise ValueError: naming the option, where ``env_kwargs`` gives one of them another value than the controller's
    """
    carried = {key: value for key, value in carried_env_kwargs(model_path).items() if _accepted(env_id, key)}
    clashes = [key for key in carried if key in env_kwargs and env_kwargs[key] != carried[key]]
    if clashes:
        named = ", ".join(f"{key}={env_kwargs[key]!r} (trained with {carried[key]!r})" for key in clashes)
        raise ValueError(
            f"The controller {model_path} trained with other task options than the task it is to be guided on: "
            f"{named}. It sees, or moves, another body there: guide it with its own, or leave them out (they are "
            "carried from its run)."
        )
    return {**carried, **env_kwargs}


def training_task(model_path: Path, max_episode_steps: int | None = None) -> gym.Env:
    """
    The task a zoo run trained on, rebuilt from its saved settings: its ID, ``env_kwargs`` and ``env_wrapper``.

    :param model_path: the run's final model (its saved settings beside it)
    :param max_episode_steps: episodes end after this many steps (None: the task's)
    """
    from rl_zoo3.utils import get_wrapper_class

    hyperparams = zoo_saved(model_path, "config.yml")
    kwargs = zoo_env_kwargs(model_path) | carried_env_kwargs(model_path)
    kwargs |= {"max_episode_steps": max_episode_steps} if max_episode_steps else {}
    env = gym.make(zoo_env_id(model_path), **kwargs)
    wrapper = get_wrapper_class(hyperparams)
    return env if wrapper is None else wrapper(env)


def statistics_venv(model_path: Path) -> VecEnv:
    """
    The run's task as the zoo wrapped it below its ``VecNormalize`` (:func:`training_task`, then the run's
    ``vec_env_wrapper``, if any): the env its saved statistics are loaded onto.
    """
    from rl_zoo3.utils import get_wrapper_class

    venv: VecEnv = DummyVecEnv([lambda: training_task(model_path)])
    wrapper = get_wrapper_class(zoo_saved(model_path, "config.yml"), "vec_env_wrapper")
    return venv if wrapper is None else wrapper(venv)


def load_zoo_model(
    model_path: Path, env: DummyVecEnv | None = None, algo: str | None = None
) -> tuple[BaseAlgorithm, VecNormalize | None]:
    """
    Load a model the zoo saved, with its ``VecNormalize`` statistics if it has some (frozen, apart from the model: the
    caller normalises what the model sees, e.g. :func:`~sb3_pilot.experiments.challenges.stages.play_episodes`).

    :param model_path: ``<run folder>/<env name>.zip``, or any SB3 zip with ``algo`` given
    :param env: the env to attach (needed to load the replay buffer); None loads the policy alone (no buffer,
        :func:`~sb3_pilot.common.saved_models.without_replay_buffer`)
    :param algo: the zoo algorithm that saved it (None: :func:`zoo_algo`)
    :return: the model and its (frozen) ``VecNormalize`` or None
    """
    from rl_zoo3 import ALGOS

    register()  # ``udpo`` among the zoo's algorithms, in whichever process this runs
    algo = algo or zoo_algo(model_path)
    stats = vecnormalize_path(model_path)
    vec_normalize = None
    if stats.exists():
        vec_normalize = VecNormalize.load(str(stats), env or statistics_venv(model_path))
        vec_normalize.training = False
    if env is None:  # a HER buffer cannot be built without the env: the policy alone
        return ALGOS[algo].load(model_path, device="cpu", custom_objects=without_replay_buffer()), vec_normalize
    return ALGOS[algo].load(model_path, env=vec_normalize or env, device="cpu"), vec_normalize


def load_zoo_run(
    model_path: str | os.PathLike,
    algo: str,
    env_id: str,
    seed: int = 0,
    device: str = "auto",
    buffer_size: int | None = 1,
    env_kwargs: dict[str, Any] | None = None,
) -> tuple[BaseAlgorithm, VecEnv]:
    """
    The model of a zoo run, with its env rebuilt as the zoo's ``enjoy`` rebuilds it (``rl_zoo3.create_test_env``): the
    run's ``env_wrapper``, ``vec_env_wrapper``, ``normalize`` and ``frame_stack`` (its saved ``config.yml``), its
    ``env_kwargs`` (:func:`zoo_env_kwargs`) and its ``VecNormalize`` statistics, frozen, inside the env.

    :param model_path: ``<run folder>/<env name>.zip`` (:func:`find_zoo_run`)
    :param algo: the zoo algorithm that saved it (``sac``, ``td3``, ``tqc``, ``udpo``, ``lean_sac``, ...)
    :param env_id: its task
    :param seed: seed of the env
    :param device: the model's device
    :param buffer_size: the replay buffer's size (1: no room is allocated, for a model that acts only; None: the run's)
    :param env_kwargs: task options over the run's own
    :return: the model (its env attached) and the env
    """
    from rl_zoo3 import ALGOS
    from rl_zoo3.utils import create_test_env, get_saved_hyperparams

    register()
    model_path = Path(model_path)
    hyperparams, stats_path = get_saved_hyperparams(str(zoo_settings_dir(model_path)), norm_reward=False, test_mode=True)
    env = create_test_env(
        env_id,
        stats_path=stats_path,
        seed=seed,
        should_render=False,
        hyperparams=hyperparams,
        env_kwargs={**zoo_env_kwargs(model_path), **(env_kwargs or {})},
        vec_env_cls=DummyVecEnv,
    )
    kwargs = {} if buffer_size is None else {"buffer_size": buffer_size}
    return ALGOS[algo].load(model_path, env=env, device=device, **kwargs), env
