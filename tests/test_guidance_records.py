"""``benchmarks.guidance_records``: a guided episode's committed record (its length, its last steps' movement)."""

from benchmarks.guidance_records import LAST_STEPS, stage_record


def test_stage_record_of_guided_and_unguided_episodes() -> None:
    still = [[0.0, 0.0]] * (LAST_STEPS + 5)  # stopped from the start
    walking = [[0.01 * step, 0.0] for step in range(LAST_STEPS + 11)]
    guided = {
        "successes": [0.0, 1.0],
        "final_distances": [3.0, 0.4],
        "horizon": 22,
        "switch_distance": None,
        "episodes": [{"achieved_goals": still, "landmarks": still}, {"achieved_goals": walking, "landmarks": walking}],
    }
    record = stage_record(guided)
    assert record["steps"] == [LAST_STEPS + 4, LAST_STEPS + 10] and record["horizon"] == 22
    assert record["moved_last_200"][0] == 0.0 and abs(record["moved_last_200"][1] - 0.01 * LAST_STEPS) < 1e-9
    unguided = stage_record({"successes": [0.0], "final_distances": [7.0], "episodes": [{"desired_goal": [1.0, 2.0]}]})
    assert unguided == {"successes": [0.0], "final_distances": [7.0]}
