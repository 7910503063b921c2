#!/bin/bash
# FetchPush with the 50k-step warm-up (README, sixth sitting), from the repository root:
#   bash zoo_runs/sources/fetchpush/seeds.sh udpo|udpoa|sac SEED [INITIAL_TEMPERATURE]
# udpo: UDPO + HER, linearised entropy term, lambda 1e-4 (FETCH_PUSH_FAST); udpoa: the same with an initial temperature
# of INITIAL_TEMPERATURE (default 0.001; SB3's "auto" starts at 1); sac: LeanSAC + HER. Seed 2's udpo and sac ran with
# -n 175000.
cd "$(dirname "$0")/../../.." && source .venv/bin/activate
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 MUJOCO_GL=osmesa
COMMON="gamma:0.95 tau:0.05 learning_rate:0.001 batch_size:256 n_envs:1 train_freq:1 gradient_steps:1 learning_starts:50000 normalize:True policy_kwargs:dict(net_arch=[256,256]) planner_learning_rate:0.001 inverse_dynamics_learning_rate:0.001"
RECIPE="gamma:0.95 tau:0.05 learning_rate:0.001 batch_size:256 n_envs:1 train_freq:1 gradient_steps:1 learning_starts:50000 normalize:True target_entropy:0.0 policy_kwargs:dict(net_arch=[256,256])"
if [ "$1" = udpo ]; then
python -m sb3_pilot.experiments.zoo train --algo udpo --env Pilot/FetchPush-v0 --conf-file cpu/udpo.yml \
    -f /tmp/fpls1e4s$2/udpo --seed $2 -n 150000 --num-threads 1 --eval-freq 12500 --eval-episodes 20 --save-freq 25000 \
    --log-interval 100 -params $COMMON planner_coef:0.0001 target_entropy:0.0 "entropy_term:'linearised'"
elif [ "$1" = udpoa ]; then
python -m sb3_pilot.experiments.zoo train --algo udpo --env Pilot/FetchPush-v0 --conf-file cpu/udpo.yml \
    -f /tmp/fpla1e4${3:+t$3}s$2/udpo --seed $2 -n 150000 --num-threads 1 --eval-freq 12500 --eval-episodes 20 --save-freq 25000 \
    --log-interval 100 -params $COMMON planner_coef:0.0001 target_entropy:0.0 "entropy_term:'linearised'" "ent_coef:'auto_${3:-0.001}'"
else
python -m sb3_pilot.experiments.zoo train --algo lean_sac --env Pilot/FetchPush-v0 --conf-file cpu/sac.yml \
    -f /tmp/fpsac50000s$2/sac --seed $2 -n 150000 --num-threads 1 --eval-freq 12500 --eval-episodes 20 \
    --save-freq 25000 --log-interval 100 -params $RECIPE
fi
