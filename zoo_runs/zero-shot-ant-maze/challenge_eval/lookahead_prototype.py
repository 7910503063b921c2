# ruff: noqa  (a throw-away prototype kept for the numbers it produced; not part of the package)
"""Prototype: pure-pursuit landmark at a fixed distance along the planned path."""
import sys, json, time
import numpy as np
from sb3_pilot import LandmarkGuidance, GoalPlanner
import sb3_pilot.experiments.ant_controller as ac


class Lookahead(LandmarkGuidance):
    lookahead = 1.2

    def landmark(self, achieved_goal, desired_goal):
        path = np.concatenate([achieved_goal[None], self.planner.plan(achieved_goal, desired_goal, horizon=self.horizon)])
        dist = np.linalg.norm(path - achieved_goal, axis=-1)
        if np.linalg.norm(desired_goal - achieved_goal) <= self.lookahead:
            return np.array(desired_goal)
        beyond = np.nonzero(dist >= self.lookahead)[0]
        if len(beyond) == 0:
            return path[-1]
        i = beyond[0]
        a, b = path[i - 1], path[i]
        # point on segment a->b at distance lookahead from achieved_goal
        d = b - a; f = a - achieved_goal
        A = d @ d; B = 2 * f @ d; C = f @ f - self.lookahead ** 2
        t = (-B + np.sqrt(max(B * B - 4 * A * C, 0))) / (2 * A) if A > 0 else 1.0
        return a + np.clip(t, 0, 1) * d


def main():
    model_path, planner_path, out = sys.argv[1], sys.argv[2], sys.argv[3]
    lookaheads = [float(x) for x in sys.argv[4].split(",")]
    seeds = [int(x) for x in sys.argv[5].split(",")]
    model = ac.load_controller(model_path)
    planner = GoalPlanner.load(planner_path)
    orig = ac.LandmarkGuidance if hasattr(ac, "LandmarkGuidance") else None
    import sb3_pilot
    rows = []
    for L in lookaheads:
        Lookahead.lookahead = L
        sb3_pilot.LandmarkGuidance = Lookahead
        t = time.time()
        per = [ac.guided_episodes(model, planner, 12, None, s, 10) for s in seeds]
        row = {"lookahead": L, "per_seed": [p["success"] for p in per],
               **{k: float(np.mean([p[k] for p in per])) for k in ("success", "reached", "flipped", "final_distance", "speed")}}
        print(row, f"{time.time()-t:.0f}s", flush=True)
        rows.append(row)
    json.dump(rows, open(out, "w"), indent=1)

main()
