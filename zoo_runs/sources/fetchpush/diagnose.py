"""
Why UDPO does not learn FetchPush where SAC + HER does: UDPO checkpoints measured against SAC + HER's trained policy.

Each checkpoint is a zoo run folder and a step (``rl_model_<step>_steps.zip`` and its ``VecNormalize`` statistics). With
SAC + HER's deterministic policy (30 episodes) and each checkpoint's sampled policy (40 episodes), it prints:

- exploration: the share of sampled episodes in which the object moves (> 2 cm), the mean smallest gripper-object
  distance, and the spread of 64 actions sampled at one state;
- actor against critic (SAC + HER's and UDPO's): on the checkpoint's own sampled states, how far the value of its
  deterministic action lies below its critic's best value over actions (Adam);
- critic (UDPO's only): on SAC + HER's states, the share where UDPO's critic values SAC + HER's action above UDPO's own,
  and the critic's best value found by Adam over actions and over plans ``s'`` through the fixed ``I``: equal values say
  that ``I`` lets the planner reach whatever the critic prefers;
- ``I``: ``|tanh(mean I(s, s')) - a|`` per action dimension on SAC + HER's transitions ``(s, a, s')``;
- planner gradient: per state dimension, the planner's std and the mean ``|gradient|`` on the plan's mean of the actor
  loss (entropy term included) and of ``lambda`` times the likelihood term (the run's ``planner_nll_beta``).

``--sac`` and ``--udpo-exploration`` checkpoints get the exploration line only (no ``--expert`` needed).

    F=/tmp/fp3/sac/lean_sac/Pilot-FetchPush-v0_1
    python zoo_runs/sources/fetchpush/diagnose.py --sac $F:100000 $F:200000 --expert $F:200000 \
        --udpo /tmp/fpL/udpo/udpo/Pilot-FetchPush-v0_1:100000 /tmp/fpL/udpo/udpo/Pilot-FetchPush-v0_1:200000
"""

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

import sb3_pilot  # noqa: F401  (registers Pilot/*)
from sb3_pilot.sac import LeanSAC
from sb3_pilot.udpo import UDPO
from sb3_pilot.udpo.policies import PlannerDistribution

ENV_ID = "Pilot/FetchPush-v0"
#: FetchPush's planner state: the 25 observation entries, then the achieved goal
STATE_NAMES = [
    *["grip_pos"] * 3, *["obj_pos"] * 3, *["obj_rel_pos"] * 3, *["fingers"] * 2, *["obj_rot"] * 3, *["obj_velp"] * 3,
    *["obj_velr"] * 3, *["grip_velp"] * 3, *["finger_vel"] * 2, *["achieved_goal"] * 3,
]  # fmt: skip


def load(spec: str, algo: type[BaseAlgorithm]) -> tuple[BaseAlgorithm, VecNormalize]:
    """
    A checkpoint ``FOLDER:STEP`` (``--save-freq``'s ``rl_model_<STEP>_steps.zip``) or a run's final model ``FOLDER``,
    and its observation normalisation.
    """
    folder, _, step = spec.partition(":")
    if step:
        model_path = Path(folder) / f"rl_model_{step}_steps.zip"
        statistics = Path(folder) / f"rl_model_vecnormalize_{step}_steps.pkl"
    else:
        model_path = Path(folder) / f"{ENV_ID.replace('/', '-')}.zip"
        statistics = Path(folder) / ENV_ID.replace("/", "-") / "vecnormalize.pkl"
    normalize = VecNormalize.load(str(statistics), DummyVecEnv([lambda: gym.make(ENV_ID)]))
    normalize.training = False
    return algo.load(model_path, env=normalize, device="cpu"), normalize


def rollouts(model: BaseAlgorithm, normalize: VecNormalize, episodes: int, seed: int, deterministic: bool) -> dict:
    """Transitions (raw observations), and per episode: object moved, smallest gripper-object distance, action spread."""
    env = gym.make(ENV_ID)
    out: dict[str, list] = {"obs": [], "next_obs": [], "actions": [], "moved": [], "closest": [], "spread": []}
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        start, closest = obs["achieved_goal"].copy(), np.inf
        for step in range(50):
            normalised = normalize.normalize_obs({key: value[None] for key, value in obs.items()})
            if step % 10 == 0:
                sampled, _ = model.predict({key: value.repeat(64, 0) for key, value in normalised.items()})
                out["spread"].append(sampled.std(0))
            action, _ = model.predict(normalised, deterministic=deterministic)
            next_obs, *_ = env.step(action[0])
            out["obs"].append(obs), out["next_obs"].append(next_obs), out["actions"].append(action[0])
            closest = min(closest, float(np.linalg.norm(obs["observation"][3:6] - obs["observation"][:3])))
            obs = next_obs
        out["moved"].append(np.linalg.norm(obs["achieved_goal"] - start) > 0.02)
        out["closest"].append(closest)
    return out


def as_tensors(normalize: VecNormalize, raw: list[dict[str, np.ndarray]]) -> dict[str, th.Tensor]:
    batch = normalize.normalize_obs({key: np.stack([obs[key] for obs in raw]) for key in raw[0]})
    return {key: th.as_tensor(value, dtype=th.float32) for key, value in batch.items()}


def exploration_line(name: str, model: BaseAlgorithm, normalize: VecNormalize) -> str:
    """Exploration of the sampled policy, and the gap between the deterministic actor and its critic's best action."""
    data = rollouts(model, normalize, 40, 2000, deterministic=False)
    obs = as_tensors(normalize, data["obs"])
    model.policy.set_training_mode(False)
    critic = model.policy.critic

    def q_value(actions: th.Tensor) -> th.Tensor:
        values = critic.q_values(obs, actions) if isinstance(model, UDPO) else th.stack(critic(obs, actions))
        return values.amin(dim=0).squeeze(-1)

    with th.no_grad():
        actions = th.as_tensor(model.predict({key: value.numpy() for key, value in obs.items()}, deterministic=True)[0])
        actor_value = q_value(actions)
    best = best_value(lambda pre: q_value(th.tanh(pre)), th.atanh(actions.clamp(-0.999, 0.999)))
    return (
        f"{name}: sampled episodes moving the object {np.mean(data['moved']):.2f}, closest gripper-object distance "
        f"{np.mean(data['closest']):.3f} m, action std at a state {np.mean(data['spread'], 0).round(2)}; "
        f"on its own states Q(actor) {actor_value.mean():.3f}, critic's best {best.mean():.3f}"
    )


def best_value(objective, start: th.Tensor, steps: int = 200) -> th.Tensor:
    """Adam ascent of ``objective`` (a per-row value) from ``start``: the values reached."""
    variable = start.detach().clone().requires_grad_(True)
    optimizer = th.optim.Adam([variable], lr=0.05)
    for _ in range(steps):
        optimizer.zero_grad()
        (-objective(variable).mean()).backward()
        optimizer.step()
    with th.no_grad():
        return objective(variable)


def diagnose_udpo(spec: str, expert: dict) -> None:
    model, normalize = load(spec, UDPO)
    policy = model.policy
    policy.set_training_mode(False)
    print(exploration_line(f"UDPO {spec}", model, normalize))

    obs, next_obs = as_tensors(normalize, expert["obs"]), as_tensors(normalize, expert["next_obs"])
    expert_actions = th.as_tensor(np.stack(expert["actions"]), dtype=th.float32)
    planner, inverse_dynamics = policy.state_planner, policy.inverse_dynamics

    def q_value(actions: th.Tensor) -> th.Tensor:
        return policy.critic.q_values(obs, actions).amin(dim=0).squeeze(-1)

    def q_through_inverse_dynamics(plans: th.Tensor) -> th.Tensor:
        return q_value(th.tanh(inverse_dynamics.distribution_params(state, plans)[0]))

    with th.no_grad():
        state, next_state = planner.planner_state(obs), planner.planner_state(next_obs)
        plan = policy.plan_and_act(obs, deterministic=True)
        q_expert, q_own = q_value(expert_actions), q_value(plan.actions)
        fitted = th.tanh(inverse_dynamics.distribution_params(state, next_state)[0])
    over_actions = best_value(lambda pre: q_value(th.tanh(pre)), th.atanh(plan.actions.clamp(-0.999, 0.999)))
    over_plans = best_value(q_through_inverse_dynamics, plan.planned_next_state)
    print(
        f"  critic on SAC + HER's states: Q(a_SAC) {q_expert.mean():.3f}, Q(a_UDPO) {q_own.mean():.3f}, "
        f"Q(a_SAC) > Q(a_UDPO) on {(q_expert > q_own).float().mean():.2f}; best over actions {over_actions.mean():.3f}, "
        f"over plans through I {over_plans.mean():.3f}"
    )
    print(f"  |I(s, s'_SAC) - a_SAC| per action dimension: {(fitted - expert_actions).abs().mean(0).numpy().round(3)}")

    # The planner's gradient on its mean: the actor loss against lambda * likelihood term, on the checkpoint's own states
    own = rollouts(model, normalize, 20, 3000, deterministic=False)
    obs, next_obs = as_tensors(normalize, own["obs"]), as_tensors(normalize, own["next_obs"])
    with th.no_grad():
        distribution = planner.distribution(obs)
    mean = distribution.delta_mean.clone().requires_grad_(True)
    leaf = PlannerDistribution(distribution.state, mean, distribution.delta_log_std)
    planner.distribution = lambda _obs: leaf  # plan_and_act samples from the leaf (an instance attribute over the method)
    try:
        plan = policy.plan_and_act(obs)
    finally:
        del planner.distribution
    ent_coef = model.log_ent_coef.exp().detach() if model.log_ent_coef is not None else model.ent_coef_tensor
    actor_loss = (ent_coef * plan.log_prob - policy.critic.q_values(obs, plan.actions).amin(dim=0).squeeze(-1)).mean()
    (actor_grad,) = th.autograd.grad(actor_loss, leaf.delta_mean)
    likelihood = model.planner_coef * leaf.beta_nll(planner.planner_state(next_obs), model.planner_nll_beta).mean()
    (likelihood_grad,) = th.autograd.grad(likelihood, leaf.delta_mean)
    gripper = [0, 1, 2, 20, 21, 22]
    print(
        f"  planner gradient (lambda {model.planner_coef}, beta {model.planner_nll_beta}): |likelihood| / |actor| "
        f"{likelihood_grad.norm() / actor_grad.norm():.2f} over all dimensions, "
        f"{likelihood_grad[:, gripper].norm() / actor_grad[:, gripper].norm():.2f} over the gripper's position and velocity"
    )
    std = distribution.delta_log_std.exp().median(dim=0).values
    for label, values in (
        ("planner std (median)", std),
        ("|actor gradient|", actor_grad.abs().mean(0)),
        ("|likelihood gradient|", likelihood_grad.abs().mean(0)),
    ):
        named = zip(STATE_NAMES, values.tolist(), strict=True)
        print(f"  {label:>22}: " + " ".join(f"{name}:{value:.1e}" for name, value in named))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--expert", help="SAC + HER checkpoint FOLDER:STEP whose policy pushes (needed with --udpo)")
    parser.add_argument("--sac", nargs="*", default=[], help="SAC + HER checkpoints FOLDER:STEP (exploration only)")
    parser.add_argument("--udpo", nargs="*", default=[], help="UDPO checkpoints FOLDER:STEP")
    parser.add_argument("--udpo-exploration", nargs="*", default=[], help="UDPO checkpoints FOLDER:STEP (exploration only)")
    args = parser.parse_args()
    if args.udpo and not args.expert:
        parser.error("--udpo compares UDPO's critic with an expert's actions: give --expert")
    th.set_num_threads(1)
    if args.udpo:
        expert = rollouts(*load(args.expert, LeanSAC), 30, 1000, deterministic=True)
        print(f"expert {args.expert}: deterministic episodes moving the object {np.mean(expert['moved']):.2f}")
    for spec in args.sac:
        print(exploration_line(f"SAC + HER {spec}", *load(spec, LeanSAC)), flush=True)
    for spec in args.udpo_exploration:
        print(exploration_line(f"UDPO {spec}", *load(spec, UDPO)), flush=True)
    for spec in args.udpo:
        diagnose_udpo(spec, expert)


if __name__ == "__main__":
    main()
