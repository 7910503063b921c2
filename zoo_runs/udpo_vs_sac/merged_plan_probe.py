import time
import torch as th
from sb3_pilot.experiments.benchmarks.udpo_vs_sac import TASKS, make_model
th.set_num_threads(1)
m = make_model("udpo", TASKS["fetch-reach"], 0, {})
m.learn(1500)
d = m.replay_buffer.sample(256, env=m._vec_normalize_env)
o, no = d.observations, d.next_observations
both = {k: th.cat([o[k], no[k]]) for k in o}
p = m.policy
def t(f, n=300):
    for _ in range(20): f()
    s = time.perf_counter()
    for _ in range(n): f()
    return (time.perf_counter() - s) / n * 1e3
for rep in range(3):
    sep = t(lambda: (p.plan_and_act(o).log_prob.sum().backward(inputs=list(p.state_planner.parameters())), p.plan_and_act(no)) )
    def merged():
        pl = p.plan_and_act(both)
        pl.log_prob[:256].sum().backward(inputs=list(p.state_planner.parameters()))
    mer = t(merged)
    print(f"separate {sep:.3f} ms, merged {mer:.3f} ms")
