"""
Would one planner + inverse-dynamics forward over ``[s; s']`` (batch 2 x 256) beat UDPO's two (``plan_and_act(s)``
with gradients, then ``plan_and_act(s')``)? Times both, with the planner's backward, on ``udpo_vs_sac``'s FetchReach
task after 1500 steps (64x64 networks, one thread), three repetitions of 300 calls:

    OMP_NUM_THREADS=1 python zoo_runs/udpo_vs_sac/merged_plan_probe.py
"""

import time
from collections.abc import Callable

import torch as th

from sb3_pilot.experiments.benchmarks.udpo_vs_sac import TASKS, make_model

th.set_num_threads(1)
model = make_model("udpo", TASKS["fetch-reach"], 0, {})
model.learn(1500)
batch = model.replay_buffer.sample(256, env=model._vec_normalize_env)
obs, next_obs = batch.observations, batch.next_observations
both = {key: th.cat([obs[key], next_obs[key]]) for key in obs}
policy = model.policy
planner_parameters = list(policy.state_planner.parameters())


def ms_per_call(step: Callable[[], None], calls: int = 300) -> float:
    for _ in range(20):
        step()
    start = time.perf_counter()
    for _ in range(calls):
        step()
    return (time.perf_counter() - start) / calls * 1e3


def separate() -> None:
    policy.plan_and_act(obs).log_prob.sum().backward(inputs=planner_parameters)
    with th.no_grad():
        policy.plan_and_act(next_obs)


def merged() -> None:
    policy.plan_and_act(both).log_prob[:256].sum().backward(inputs=planner_parameters)


for _ in range(3):
    print(f"separate {ms_per_call(separate):.3f} ms, merged {ms_per_call(merged):.3f} ms")
