#!/usr/bin/env bash
# The GPU checks of the fast path (CUDA graphs + device-resident HER buffer), in one go, on a bare 16-core GPU machine
# with Python 3.12, torch (CUDA), numpy and pandas but no SB3 / Gymnasium / MuJoCo / gymnasium-robotics and no package
# registry, in under 4 minutes:
#
#   1. installs the wheels of .gpu_wheels/wheels (made here by benchmarks/gpu_wheels.sh) and sets up EGL
#      (benchmarks/gpu_setup.sh);
#   2. renders a few ReacherImage and FetchReachImage frames (ms per step);
#   3. runs the tests that need CUDA (in tests/test_cuda_graph.py and tests/test_device_buffer.py; CI skips them);
#   4. runs benchmarks/gpu_speed.py in the time left (it skips the cases it has no time for, and says so).
#
# Logs and results go to $OUT (gpu_fast_path.log, cuda_tests.log, gpu_speed.jsonl, gpu_speed.md).
# From the repository root, with the device tool: run(command="bash benchmarks/gpu_fast_path.sh", carry=[".gpu_wheels"],
# timeout_s=300).
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-gpu_fast_path_out}
mkdir -p "$OUT"
exec > >(tee "$OUT/gpu_fast_path.log") 2>&1
TOTAL_S=${TOTAL_S:-230}
start=$SECONDS
step() { echo "== [$((SECONDS - start)) s] $*"; }

step "machine"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
python3 -c "import sys, torch; print(sys.version.split()[0], 'torch', torch.__version__, 'cuda', torch.cuda.is_available())"

step "wheels and EGL"
source benchmarks/gpu_setup.sh || exit 1

step "EGL rendering"
python3 - <<'EOF'
import time

import gymnasium as gym
import mujoco
import stable_baselines3

from sb3_pilot.envs import register_envs

register_envs()
print("mujoco", mujoco.__version__, "stable-baselines3", stable_baselines3.__version__, "gymnasium", gym.__version__)
for env_id in ("Pilot/ReacherImage-v0", "Pilot/FetchReachImage-v0"):
    env = gym.make(env_id)
    obs, _ = env.reset(seed=0)
    start = time.perf_counter()
    for _ in range(200):
        obs, *_, truncated, _ = env.step(env.action_space.sample())
        if truncated:
            env.reset()
    print(f"{env_id}: {(time.perf_counter() - start) / 200 * 1e3:.3f} ms per step with its frame, frame mean {obs['observation'].mean():.1f}")
EOF

step "CUDA tests"
# the tests that need CUDA (the others run in CI): captured vs eager steps (LeanSAC, UDPO), device buffers on CUDA
timeout 120 python3 -m pytest -q -p no:cacheprovider -rs -k "cuda or captured or draw_in_graph" \
    tests/test_cuda_graph.py tests/test_device_buffer.py 2>&1 | tee "$OUT/cuda_tests.log"
echo "pytest exit status ${PIPESTATUS[0]}"

left=$((TOTAL_S - (SECONDS - start)))
step "benchmark (${left} s left)"
if [ "$left" -gt 30 ]; then
    timeout "$left" python3 -m benchmarks.gpu_speed --device cuda --out "$OUT" --budget-s $((left - 45)) ${GPU_SPEED_ARGS:-}
    echo "gpu_speed exit status $?"
fi
step "done"
