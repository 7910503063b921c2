#!/usr/bin/env bash
# The pixel recipe's runs (python -m benchmarks.image_recipe, see its docstring) on a lent 16-core GPU machine, in one
# call under the device's 10-minute cap: SAC + HER with hyperparams/image/sac.yml and its variants, VARIANTS x SEEDS
# runs side by side (each one process with --device cuda on the one GPU, OMP_NUM_THREADS=1), up to STEPS env steps,
# stopped (keeping their evaluations) when TOTAL_S seconds of the whole script are near.
#
#   1. installs the carried wheels and sets up EGL rendering (benchmarks/gpu_setup.sh; the wheels are made here by
#      benchmarks/gpu_wheels.sh);
#   2. with FAST=1 (the default), tries the GPU fast path (the image_recipe variant `fast`: CUDA graphs and the HER
#      buffer on the device) on one short run of the first variant; where it finishes, every variant runs with `+fast`,
#      else (its log's tail shown) they run eager;
#   3. runs python -m benchmarks.image_recipe --device cuda --jobs <all runs> --time-limit <what is left>, in
#      runs/image-recipe-gpu on that machine (GPU use logged every minute);
#   4. writes to $OUT: gpu_image_recipe.log (this script's output, the table at its end), summary.md, summary.json and
#      runs.tar.gz (each run's command.txt, status.json, train.log, monitor files and evaluations.npz; no models).
#
# From the repository root, with the device tool:
#   run(command="bash benchmarks/gpu_image_recipe.sh", carry=[".gpu_wheels"], timeout_s=600)
# Settings (environment variables; their defaults below): TASK, VARIANTS, SEEDS, STEPS, EVAL_FREQ, EVAL_EPISODES,
# FAST, TOTAL_S (the script's wall time, setup and report included). STEPS is a cap: the time limit stops the runs
# first, keeping their evaluations so far. Back here, the runs' table again, or with other runs:
#   mkdir -p runs/image-recipe-gpu && tar xzf runs.tar.gz -C runs/image-recipe-gpu
#   python -m benchmarks.image_recipe --root runs/image-recipe-gpu --report [the same task, variants, seeds, steps ...]
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-gpu_image_recipe_out}
mkdir -p "$OUT"
exec > >(tee "$OUT/gpu_image_recipe.log") 2>&1
TASK=${TASK:-Pilot/ReacherImage-v0}
VARIANTS=${VARIANTS:-hidden+goalnorm+zoorl+stack3 hidden+goalnorm+zoorl+stack3+goalpred}
SEEDS=${SEEDS:-0 1}
STEPS=${STEPS:-150000}
EVAL_FREQ=${EVAL_FREQ:-5000}
FAST=${FAST:-1}
EVAL_EPISODES=${EVAL_EPISODES:-20}
TOTAL_S=${TOTAL_S:-540}
ROOT=runs/image-recipe-gpu
start=$SECONDS
step() { echo "== [$((SECONDS - start)) s] $*"; }

step "machine"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
nproc

step "wheels and EGL"
source benchmarks/gpu_setup.sh || exit 1
python3 -c "import sys, torch; print(sys.version.split()[0], 'torch', torch.__version__, 'cuda', torch.cuda.is_available())"

if [ "$FAST" = 1 ]; then
    # one short run of the first variant on the fast path (1000 warm-up steps of zoorl, then 500 captured steps)
    smoke="$(cut -d' ' -f1 <<<"$VARIANTS")+fast"
    step "fast path: one 1500-step run of $smoke"
    python3 -m benchmarks.image_recipe --task "$TASK" --variants "$smoke" --seeds 0 --steps 1500 --eval-freq 1500 \
        --eval-episodes 2 --root runs/gpu-fast-smoke --device cuda --time-limit 120 | tail -4
    if python3 -c "import json, sys; sys.exit(not json.load(open(sys.argv[1]))['finished'])" \
        "runs/gpu-fast-smoke/$smoke/seed_0/status.json" 2>/dev/null; then
        VARIANTS=$(for variant in $VARIANTS; do printf '%s+fast ' "$variant"; done)
        step "fast path works: variants $VARIANTS"
    else
        tail -20 "runs/gpu-fast-smoke/$smoke/seed_0/train.log"
        step "fast path failed (log above): the variants run eager"
    fi
    cp -r runs/gpu-fast-smoke "$OUT/fast-smoke" 2>/dev/null
fi

# the runs' time limit: what is left, less the stop's grace (image_recipe.GRACE_S) and the report's time
runs=$(($(wc -w <<<"$VARIANTS") * $(wc -w <<<"$SEEDS")))
limit=$((TOTAL_S - (SECONDS - start) - 45))
step "image_recipe: $runs runs side by side, at most $STEPS env steps, stopped after $limit s"
(while sleep 60; do nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv,noheader; done) &
monitor=$!
# shellcheck disable=SC2086 # VARIANTS and SEEDS are lists
python3 -m benchmarks.image_recipe --task "$TASK" --variants $VARIANTS --seeds $SEEDS --steps "$STEPS" \
    --eval-freq "$EVAL_FREQ" --eval-episodes "$EVAL_EPISODES" --root "$ROOT" --device cuda --jobs "$runs" \
    --time-limit "$limit"
echo "image_recipe exit status $?"
kill "$monitor"

step "results"
cp "$ROOT/summary.md" "$ROOT/summary.json" "$OUT/"
tar czf "$OUT/runs.tar.gz" --exclude='*.zip' --exclude=summary.md --exclude=summary.json -C "$ROOT" .
ls -l "$OUT"
step "done"
