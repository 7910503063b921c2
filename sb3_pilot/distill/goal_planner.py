"""The goal planner ``f(g' | g, g_target)`` of PILoT's distillation stage (paper section 3.2)."""

from __future__ import annotations

import functools
import os
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from gymnasium import spaces
from gymnasium.envs.registration import load_env_creator
from stable_baselines3.common.torch_layers import create_mlp
from stable_baselines3.common.vec_env import VecEnv
from torch import nn

from sb3_pilot.common.distributions import LOG_STD_MAX, LOG_STD_MIN, gaussian_log_prob
from sb3_pilot.common.utils import check_number, task_id
from sb3_pilot.distill.goal_map import GoalMap
from sb3_pilot.version import __version__

#: Groups of task IDs declared (:func:`share_goal_space`) to have goals of the same meaning in the same coordinates:
#: a planner distilled on one task of a group may plan for any task of the group.
SHARED_GOAL_SPACES: list[frozenset[str]] = []

#: Known maps between the goal coordinates of two tasks (:func:`share_goal_space` with ``goal_map``):
#: ``GOAL_MAPS[(first, second)]`` maps the first task's goals to the second's.
GOAL_MAPS: dict[tuple[str, str], GoalMap] = {}


def env_goal_space(env: gym.Env | VecEnv) -> str | None:
    """
    The goal space a task declares: the ``goal_space_id`` attribute of its unwrapped env (of the first env of a
    ``VecEnv``). Tasks that declare the same ``goal_space_id`` have goals of the same meaning in the same coordinates,
    so a planner distilled on one plans for the others (the ``Pilot/...`` tasks declare theirs).

    :param env: a Gymnasium env or an SB3 ``VecEnv``
    :return: the declared goal space, None if the task declares none
    :raises TypeError: if ``goal_space_id`` is set but not a string
    """
    unwrapped = env.get_attr("unwrapped", indices=[0])[0] if isinstance(env, VecEnv) else env.unwrapped
    declared = getattr(unwrapped, "goal_space_id", None)
    if declared is not None and not isinstance(declared, str):
        raise TypeError(f"{type(unwrapped).__name__}.goal_space_id must be a string (or None), got {declared!r}.")
    return declared


def registered_goal_space(task: str) -> str | None:
    """
    The goal space a registered Gymnasium task declares (see :func:`env_goal_space`): read from its entry point's class
    when the class sets ``goal_space_id``, else (a property: it depends on the task's kwargs) from an instance.

    :param task: a Gymnasium ID
    :return: the declared goal space, None if the task is not registered or declares none
    """
    return _registered_goal_space(task) if task in gym.registry else None


@functools.cache
def _registered_goal_space(task: str) -> str | None:
    entry_point = gym.spec(task).entry_point
    creator = load_env_creator(entry_point) if isinstance(entry_point, str) else entry_point
    declared = getattr(creator, "goal_space_id", None)
    if declared is None or isinstance(declared, str):
        return declared
    env = gym.make(task)
    try:
        return env_goal_space(env)
    finally:
        env.close()


def _declared_shared(source_task: str, target_task: str) -> bool:
    """Whether the tasks are one, or :func:`share_goal_space` declared them to share a goal space."""
    return (
        source_task == target_task
        or any({source_task, target_task} <= group for group in SHARED_GOAL_SPACES)
        or (source_task, target_task) in GOAL_MAPS
    )


def share_goal_space(*task_ids: str, goal_map: GoalMap | None = None) -> None:
    """
    Declare that tasks share one goal space, so a planner distilled on one of them may guide the others: for tasks
    that do not declare it themselves (a ``goal_space_id`` attribute, see :func:`env_goal_space`).

    With ``goal_map``, two tasks whose goals mean the same in other coordinates, ``g_second = goal_map(g_first)``:
    e.g. ``share_goal_space("PointMaze_UMaze-v3", "AntMaze_UMaze-v5", goal_map=GoalMap(4.0))``. A planner of either
    task plans for the other through the map (both directions are declared). The same map declared again changes
    nothing; another one is refused.

    :param task_ids: Gymnasium IDs (or, for unregistered envs, class names) of the tasks (exactly two with ``goal_map``)
    :param goal_map: the map from the first task's goal coordinates to the second's (None: the same coordinates)
    """
    if len(task_ids) < 2:
        raise ValueError(f"share_goal_space needs at least two task IDs, got {task_ids}.")
    if goal_map is None:
        mapped = [pair for pair in GOAL_MAPS if set(pair) <= set(task_ids)]
        if mapped:
            raise ValueError(
                f"{mapped[0]} already share a goal space through {GOAL_MAPS[mapped[0]]}, not the same coordinates."
            )
        SHARED_GOAL_SPACES.append(frozenset(task_ids))
        return
    if len(task_ids) != 2 or task_ids[0] == task_ids[1]:
        raise ValueError(f"goal_map relates two different tasks, g_second = goal_map(g_first); got {task_ids}.")
    first, second = task_ids
    declared = GOAL_MAPS.get((first, second))
    if (
        declared is not None
        and np.array_equal(declared.matrix, goal_map.matrix)
        and np.array_equal(declared.offset, goal_map.offset)
    ):
        return  # declared again with the same map (e.g. by each evaluation in one process)
    if shares_goal_space(first, second):
        raise ValueError(f"{first!r} and {second!r} already share a goal space ({goal_map_between(first, second)}).")
    GOAL_MAPS[(first, second)], GOAL_MAPS[(second, first)] = goal_map, goal_map.inverse()


def shares_goal_space(source_task: str, target_task: str) -> bool:
    """
    :param source_task: task a planner was distilled on
    :param target_task: task it is asked to plan for
    :return: whether the two tasks are the same, declare the same goal space (:func:`registered_goal_space`), or were
        declared to share their goal space (:func:`share_goal_space`, with a map or without)
    """
    if _declared_shared(source_task, target_task):
        return True
    source_space = registered_goal_space(source_task)
    return source_space is not None and source_space == registered_goal_space(target_task)


def goal_map_between(source_task: str, target_task: str) -> GoalMap | None:
    """
    :param source_task: task a planner was distilled on
    :param target_task: task it is asked to plan for
    :return: the map from the source's goal coordinates to the target's (:func:`share_goal_space`), None for the same
        coordinates
    :raises ValueError: when the tasks do not share a goal space
    """
    if not shares_goal_space(source_task, target_task):
        raise ValueError(f"{source_task!r} and {target_task!r} were not declared to share a goal space.")
    return GOAL_MAPS.get((source_task, target_task))


class GoalPlanner(nn.Module):
    """
    Goal planner ``f(g' | g, g_target)`` (paper section 3.2): a diagonal Gaussian MLP over the change of goal
    ``g' - g``, given the achieved goal ``g`` and the target goal ``g_target``.

    It takes and returns raw goal coordinates (what the env reports in ``achieved_goal``/``desired_goal``).
    Internally, inputs are standardised with ``goal_mean``/``goal_std`` and the output is scaled by
    ``delta_scale``; these are buffers set from the distillation data and saved with the weights.

    The planner may also hold a *support*: goals the source agent really occupied (``support``, set by
    :func:`~sb3_pilot.distill.distill_goal_planner`). Snapping replaces a landmark by the nearest of them, so that it
    is a state the source reached (never inside a wall it could not enter), as planning over replay-buffer states
    does (SoRB, Eysenbach et al. 2019). :meth:`plan` snaps by default when there is a support: an imagined path plans
    each landmark from the previous one, so a landmark off the states the source visited would make the next one an
    extrapolation. :meth:`predict` (one landmark, e.g. the reward bonus's direction) does not unless asked.

    :param goal_dim: size of the goal vectors
    :param net_arch: hidden layer sizes
    :param activation_fn: activation function (a ``torch.nn`` module class)
    :param metadata: facts about the planner's origin, saved with it (``source_task``, ``n_samples``, ...)
    """

    goal_mean: th.Tensor
    goal_std: th.Tensor
    delta_scale: th.Tensor
    support: th.Tensor

    def __init__(
        self,
        goal_dim: int,
        net_arch: list[int] | None = None,
        activation_fn: type[nn.Module] = nn.ReLU,
        metadata: dict[str, Any] | None = None,
    ):
        super().__init__()
        check_number("goal_dim", goal_dim, minimum=1, integer=True)
        self.goal_dim = goal_dim
        self.net_arch = [256, 256] if net_arch is None else list(net_arch)
        self.activation_fn = activation_fn
        self.metadata = {"goal_dim": goal_dim, "sb3_pilot_version": __version__, **(metadata or {})}
        self.net = nn.Sequential(*create_mlp(2 * goal_dim, 2 * goal_dim, self.net_arch, activation_fn))
        self.register_buffer("goal_mean", th.zeros(goal_dim))
        self.register_buffer("goal_std", th.ones(goal_dim))
        self.register_buffer("delta_scale", th.ones(goal_dim))
        self.register_buffer("support", th.zeros(0, goal_dim))

    @property
    def source_task(self) -> str | None:
        """The task the planner was distilled on."""
        return self.metadata.get("source_task")

    @property
    def source_goal_space(self) -> str | None:
        """
        The goal space of the source task: as recorded at distillation (``metadata["goal_space_id"]``), else as the
        registered source task declares it (:func:`registered_goal_space`), None if neither says.
        """
        recorded = self.metadata.get("goal_space_id")
        if recorded is not None:
            return recorded
        return registered_goal_space(self.source_task) if self.source_task is not None else None

    def set_scales(self, goals: th.Tensor, deltas: th.Tensor) -> None:
        """
        Set the input standardisation and the output scale from data.

        :param goals: goals the planner will see, shape (n, goal_dim)
        :param deltas: changes of goal it will predict, shape (n, goal_dim)
        """
        self.goal_mean.copy_(goals.mean(dim=0))
        self.goal_std.copy_(goals.std(dim=0).clamp_min(1e-6))
        self.delta_scale.copy_(deltas.abs().mean(dim=0).clamp_min(1e-6))

    def set_support(self, goals: th.Tensor) -> None:
        """
        Set the goals that :meth:`predict` and :meth:`plan` snap landmarks to (``snap=True``).

        :param goals: goals the source agent really occupied, shape (m, goal_dim), raw coordinates
        """
        if goals.ndim != 2 or goals.shape[1] != self.goal_dim:
            raise ValueError(f"support goals must have shape (m, {self.goal_dim}), got {tuple(goals.shape)}.")
        self.support = goals.detach().to(self.goal_mean).clone()

    @property
    def has_support(self) -> bool:
        """Whether the planner holds goals to snap its landmarks to."""
        return len(self.support) > 0

    def snap(self, goals: th.Tensor, chunk: int = 256) -> th.Tensor:
        """
        :param goals: goals, shape (n, goal_dim), raw coordinates
        :param chunk: goals compared with the whole support at once (memory: ``chunk * len(support)`` distances)
        :return: for each goal, the nearest goal of the support
        """
        if not self.has_support:
            raise ValueError(
                "This goal planner holds no support goals to snap landmarks to (distilled with support_size=0, or saved "
                "before planners kept them): distil it again, or plan with snap=False."
            )
        nearest = [th.cdist(part, self.support).argmin(dim=1) for part in goals.split(chunk)]
        return self.support[th.cat(nearest)]

    def _outputs(self, achieved_goal: th.Tensor, desired_goal: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        """Standardise the inputs and run the network: scaled mean and log-std of ``g' - g``."""
        inputs = th.cat([achieved_goal - self.goal_mean, desired_goal - self.goal_mean], dim=-1) / self.goal_std.repeat(2)
        delta_mean, log_std = self.net(inputs).chunk(2, dim=-1)
        return delta_mean, log_std

    def distribution_params(self, achieved_goal: th.Tensor, desired_goal: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        """
        :param achieved_goal: current goals ``g``, shape (n, goal_dim), raw coordinates
        :param desired_goal: target goals ``g_target``, same shape
        :return: mean and log-std of the Gaussian over ``g' - g``, raw coordinates
        """
        delta_mean, log_std = self._outputs(achieved_goal, desired_goal)
        return delta_mean * self.delta_scale, th.clamp(log_std, LOG_STD_MIN, LOG_STD_MAX) + th.log(self.delta_scale)

    def nll(self, next_goal: th.Tensor, achieved_goal: th.Tensor, desired_goal: th.Tensor) -> th.Tensor:
        """Negative log-likelihood ``-log f(g' | g, g_target)`` of next goals, shape (n,)."""
        delta_mean, log_std = self.distribution_params(achieved_goal, desired_goal)
        return -gaussian_log_prob(next_goal - achieved_goal, delta_mean, log_std)

    def forward(self, achieved_goal: th.Tensor, desired_goal: th.Tensor, deterministic: bool = True) -> th.Tensor:
        """Next goal ``g'`` (the mean if ``deterministic``, else a sample)."""
        if deterministic:  # the hot path of the reward bonus: the mean only
            return achieved_goal + self._outputs(achieved_goal, desired_goal)[0] * self.delta_scale
        delta_mean, log_std = self.distribution_params(achieved_goal, desired_goal)
        return achieved_goal + delta_mean + th.randn_like(delta_mean) * th.exp(log_std)

    def _to_tensor(self, goals: np.ndarray, name: str) -> th.Tensor:
        goals = np.asarray(goals, dtype=np.float32)
        if goals.shape[-1:] != (self.goal_dim,) or goals.ndim > 2:
            raise ValueError(f"{name} must have shape ({self.goal_dim},) or (n, {self.goal_dim}), got {goals.shape}.")
        goals = goals.reshape(-1, self.goal_dim)
        if not np.isfinite(goals).all():
            bad = goals[~np.isfinite(goals).all(axis=1)]
            raise ValueError(f"{name} holds NaN or infinite values in {len(bad)} of its {len(goals)} goals: {bad[:3]}.")
        return th.as_tensor(goals, device=self.goal_mean.device)

    def predict(
        self, achieved_goal: np.ndarray, desired_goal: np.ndarray, deterministic: bool = True, snap: bool = False
    ) -> np.ndarray:
        """
        The immediate landmark ``g' ~ f(. | g, g_target)``.

        :param achieved_goal: current goal(s), shape (goal_dim,) or (n, goal_dim), raw coordinates
        :param desired_goal: target goal(s), same shape
        :param deterministic: return the mean instead of a sample
        :param snap: replace the landmark by the nearest support goal (a state the source reached, see :meth:`snap`)
        :return: next goal(s), same shape as ``achieved_goal``
        :raises ValueError: if a goal has the wrong size, or holds NaN or infinite values
        """
        achieved = self._to_tensor(achieved_goal, "achieved_goal")
        desired = self._to_tensor(desired_goal, "desired_goal")
        if achieved.shape != desired.shape:
            raise ValueError(f"achieved_goal and desired_goal shapes differ: {achieved.shape} vs {desired.shape}.")
        with th.inference_mode():
            next_goal = self(achieved, desired, deterministic=deterministic)
            next_goal = (self.snap(next_goal) if snap else next_goal).cpu().numpy()
        return next_goal.reshape(np.shape(achieved_goal))

    def plan(
        self,
        achieved_goal: np.ndarray,
        desired_goal: np.ndarray,
        horizon: int = 1,
        deterministic: bool = True,
        snap: bool | None = None,
    ) -> np.ndarray:
        """
        Imagined path: ``horizon`` landmarks chained from ``achieved_goal``, each planned from the previous one.

        :param achieved_goal: start goal(s), shape (goal_dim,) or (n, goal_dim)
        :param desired_goal: target goal(s), same shape
        :param horizon: number of landmarks ``k``
        :param deterministic: chain the means instead of samples
        :param snap: snap every landmark to the nearest support goal before planning the next one (None: if the
            planner holds support goals, see :attr:`has_support`)
        :return: landmarks, shape (horizon, goal_dim) or (n, horizon, goal_dim)
        :raises ValueError: as :meth:`predict`
        """
        check_number("horizon", horizon, minimum=1, integer=True)
        snap = self.has_support if snap is None else snap
        landmarks, goal = [], achieved_goal
        for _ in range(horizon):
            goal = self.predict(goal, desired_goal, deterministic=deterministic, snap=snap)
            landmarks.append(goal)
        return np.stack(landmarks, axis=-2)

    def save(self, path: str | os.PathLike) -> None:
        """Save weights, scales, architecture and metadata (a ``torch.save`` file)."""
        th.save(
            {
                "state_dict": self.state_dict(),
                "net_arch": self.net_arch,
                "activation_fn": self.activation_fn.__name__,
                "metadata": self.metadata,
            },
            path,
        )

    @classmethod
    def load(cls, path: str | os.PathLike, device: th.device | str = "cpu") -> GoalPlanner:
        """
        Load a planner saved with :meth:`save` (warns if it was saved by another sb3_pilot version).

        :param path: file written by :meth:`save`
        :param device: device to load the planner on
        :raises ValueError: if the file is not a goal planner written by :meth:`save`
        """
        if not os.path.isfile(path):
            raise FileNotFoundError(f"No goal planner file at {path}.")
        not_a_planner = f"{path} is not a goal planner written by GoalPlanner.save"
        try:
            data = th.load(path, map_location=device, weights_only=True)
        except Exception as error:  # torch raises many types for files it cannot read (pickle, zip, unicode, EOF...)
            raise ValueError(f"{not_a_planner}: torch cannot read it ({type(error).__name__}).") from error
        missing = {"state_dict", "net_arch", "activation_fn", "metadata"} - set(data) if isinstance(data, dict) else None
        if missing is None or missing or "goal_dim" not in data["metadata"]:
            content = sorted(data) if isinstance(data, dict) else type(data).__name__
            raise ValueError(f"{not_a_planner}: it holds {content}.")
        if not isinstance(getattr(nn, data["activation_fn"], None), type):
            raise ValueError(f"{not_a_planner}: unknown activation function {data['activation_fn']!r}.")
        metadata = data["metadata"]
        if metadata.get("sb3_pilot_version") != __version__:
            warnings.warn(
                f"Goal planner {path} was saved by sb3_pilot {metadata.get('sb3_pilot_version')}, this is {__version__}."
            )
        planner = cls(metadata["goal_dim"], data["net_arch"], getattr(nn, data["activation_fn"]), metadata=metadata)
        state_dict = {"support": th.zeros(0, metadata["goal_dim"]), **data["state_dict"]}  # none in older files
        planner.support = th.empty_like(state_dict["support"])
        planner.load_state_dict(state_dict)
        return planner.to(device)

    @classmethod
    def for_env(cls, planner: GoalPlanner | str | os.PathLike, env: gym.Env) -> tuple[GoalPlanner, GoalMap | None]:
        """
        The planner (loaded, if a path is given), after :meth:`check_env` has accepted ``env``, and the map from its
        goal coordinates to the env's.

        :param planner: a goal planner or the path of its file
        :param env: the goal env it will plan for
        :return: the planner, and the map from its goal coordinates to the env's (None: the same coordinates)
        """
        planner = planner if isinstance(planner, GoalPlanner) else cls.load(planner)
        return planner, planner.check_env(env)

    def check_env(self, env: gym.Env) -> GoalMap | None:
        """
        Refuse an env this planner cannot plan for: one whose goal entries have another size, or whose task does not
        share the goal space of the planner's source task: the same task, the same declared ``goal_space_id``
        (:func:`env_goal_space`, :attr:`source_goal_space`), or tasks declared by :func:`share_goal_space`.

        :param env: a goal env (Dict observation with ``achieved_goal`` and ``desired_goal``)
        :return: the map from the planner's goal coordinates to the env's, None when they are the same
        :raises ValueError: naming what does not fit
        """
        obs_space = env.observation_space
        if not isinstance(obs_space, spaces.Dict) or not {"achieved_goal", "desired_goal"} <= set(obs_space.spaces):
            raise ValueError(
                f"A goal planner needs a goal env (Dict observation with 'achieved_goal' and 'desired_goal'), got {obs_space}."
            )
        for key in ("achieved_goal", "desired_goal"):
            if obs_space[key].shape != (self.goal_dim,):
                raise ValueError(
                    f"The goal planner plans {self.goal_dim}-dim goals but the env's '{key}' has shape {obs_space[key].shape}."
                )
        target_task = task_id(env)
        if self.source_task is None:
            raise ValueError("The goal planner has no 'source_task' in its metadata: distil it with distill_goal_planner.")
        source_space, target_space = self.source_goal_space, env_goal_space(env)
        same_space = source_space is not None and source_space == target_space
        if not (same_space or _declared_shared(self.source_task, target_task)):
            raise ValueError(
                f"The goal planner was distilled on '{self.source_task}' (goal space {source_space!r}), whose goal space "
                f"is not that of '{target_task}' (goal space {target_space!r}). If their goals have the same meaning in "
                f"the same coordinates, declare it with sb3_pilot.share_goal_space({self.source_task!r}, "
                f"{target_task!r}) (or, in an env class of yours, a goal_space_id attribute); if in coordinates related "
                "by a known affine map, add goal_map=sb3_pilot.GoalMap(matrix, offset) (target goal = matrix @ source "
                "goal + offset)."
            )
        goal_map = None if same_space else GOAL_MAPS.get((self.source_task, target_task))
        if goal_map is not None:
            goal_map.check_goal_dim(self.goal_dim)
        return goal_map
