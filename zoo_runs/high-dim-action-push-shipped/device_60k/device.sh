#!/bin/bash
# device: High-Dim Push pilot stages (frozen shipped planner), N seeds at once, one core each.
# usage: bash .dev/hdp.sh start|more UNTIL_SECONDS [SEEDS]
T0=$(date +%s)
export PYTHONPATH=/tmp/stub:/tmp/site:$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONUNBUFFERED=1 CUDA_VISIBLE_DEVICES=""
unset MUJOCO_GL
if [ "$1" = start ]; then
  mkdir -p /tmp/site /tmp/stub /tmp/hdp && tar xJf .dev/site.tar.xz -C /tmp/site || exit 1
  nproc; lscpu | grep "Model name"; free -g | head -2
  python3 -c "import sys, pandas, numpy, torch; print(sys.version, 'pandas', pandas.__version__, 'numpy', numpy.__version__, 'torch', torch.__version__)"
  if ! python3 -c "import rliable.library, rliable.metrics" 2>/tmp/rl.err; then
    tail -2 /tmp/rl.err; echo "rliable stubbed (statistics are computed at home, not here)"
    mkdir -p /tmp/stub/rliable && touch /tmp/stub/rliable/__init__.py /tmp/stub/rliable/library.py /tmp/stub/rliable/metrics.py
  fi
  python3 -c "
import gymnasium as gym, sb3_pilot, sb3_pilot.experiments.challenges, mujoco, stable_baselines3, rl_zoo3
env = gym.make('Pilot/FetchPushHighDim-v0'); o, _ = env.reset(seed=0); print('env ok', env.action_space, o['observation'].dtype, mujoco.__version__)" || exit 1
  setsid nohup python3 -m sb3_pilot.experiments.challenges high-dim-action-push --reuse-shipped --budget cpu \
      --seeds ${3:-14} --stages pilot --jobs ${3:-14} --root /tmp/hdp --no-progress > /tmp/hdp/run.log 2>&1 < /dev/null &
  sleep 1; echo "launched at $(date)"
fi
mkdir -p /tmp/hdp
while [ $(( $(date +%s) - T0 )) -lt $2 ]; do sleep 15; done
for f in /tmp/hdp/high-dim-action-push-shipped/models/seed_*/pilot/progress.csv; do
  echo "$f $(tail -1 $f | cut -d, -f6-8)"; done
grep -h "" /tmp/hdp/run.log | tail -5
tar czf $OUT/hdp_$1.tgz --exclude='*.zip' --exclude='*replay_buffer*' -C /tmp hdp && ls -la $OUT
