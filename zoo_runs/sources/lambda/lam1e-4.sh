#!/bin/bash
# lambda 1e-4 (UDPO's default entropy term) on the sources, seeds 0-2 (README, sixth sitting), from the repository root:
#   bash zoo_runs/sources/lambda/lam1e-4.sh
# each evaluations.npz -> npz/<task>_lam1e-4_seed_<s>.npz
cd "$(dirname "$0")/../../.." && source .venv/bin/activate
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 MUJOCO_GL=osmesa
N=zoo_runs/sources/lambda/npz; S=/tmp/s36/lam
for seed in 0 1 2; do
  python -m sb3_pilot.experiments.zoo train --algo udpo --env Pilot/FetchReach-v0 --conf-file cpu/udpo.yml \
    -f $S/fetchreach/seed_$seed --seed $seed -n 10000 --num-threads 1 --eval-freq 1000 --eval-episodes 10 \
    -params buffer_size:10000 gamma:0.95 learning_rate:0.001 batch_size:256 learning_starts:1000 \
    "policy_kwargs:{'net_arch': [64, 64]}" normalize:True planner_learning_rate:0.001 inverse_dynamics_learning_rate:0.001 \
    planner_coef:0.0001 > $S/fetchreach_seed_$seed.log 2>&1
  cp $S/fetchreach/seed_$seed/udpo/Pilot-FetchReach-v0_1/evaluations.npz $N/fetchreach_lam1e-4_seed_$seed.npz
done
for seed in 0 1 2; do
  python -m sb3_pilot.experiments.zoo train --algo udpo --env Pilot/Maze2D-v0 --conf-file cpu/udpo.yml \
    -f $S/maze2d/seed_$seed --seed $seed -n 20000 --num-threads 1 --eval-freq 2000 --eval-episodes 10 \
    -params buffer_size:20000 planner_coef:0.0001 --env-kwargs "goal_distribution:'uniform'" \
    --eval-env-kwargs "goal_distribution:'far'" > $S/maze2d_seed_$seed.log 2>&1
  cp $S/maze2d/seed_$seed/udpo/Pilot-Maze2D-v0_1/evaluations.npz $N/maze2d_lam1e-4_seed_$seed.npz
done
for seed in 0 1 2; do
  python -m sb3_pilot.experiments.zoo train --algo udpo --env Pilot/Reacher-v0 --conf-file cpu/udpo.yml \
    -f $S/reacher/seed_$seed --seed $seed -n 40000 --num-threads 1 --eval-freq 4000 --eval-episodes 10 \
    -params buffer_size:40000 gamma:0.95 learning_rate:0.001 batch_size:256 learning_starts:1000 \
    "policy_kwargs:{'net_arch': [64, 64]}" normalize:True n_envs:1 planner_learning_rate:0.001 \
    inverse_dynamics_learning_rate:0.001 planner_coef:0.0001 > $S/reacher_seed_$seed.log 2>&1
  cp $S/reacher/seed_$seed/udpo/Pilot-Reacher-v0_1/evaluations.npz $N/reacher_lam1e-4_seed_$seed.npz
done
for seed in 0 1 2; do
  python -m sb3_pilot.experiments.zoo train --algo udpo --env Pilot/PointLocomotion-v0 --conf-file cpu/udpo.yml \
    -f $S/pointlocomotion/seed_$seed --seed $seed -n 80000 --num-threads 1 --eval-freq 10000 --eval-episodes 10 \
    -params buffer_size:100000 planner_coef:0.0001 > $S/pointlocomotion_seed_$seed.log 2>&1
  cp $S/pointlocomotion/seed_$seed/udpo/Pilot-PointLocomotion-v0_1/evaluations.npz $N/pointlocomotion_lam1e-4_seed_$seed.npz
done
