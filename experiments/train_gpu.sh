#!/usr/bin/env bash
# Trains one small-config run on a lent accelerator, in one command of under
# 10 minutes (docs/gns.md, "Training on an accelerator"):
#
#   bash experiments/train_gpu.sh NAME [--config.train.X=Y ...]
#
# sent with the ignored .whl/ carried (`make wheels` here first), and with
# runs/NAME carried too when it holds a checkpoint to resume from an
# earlier lease. On a bare machine it
#   1. installs the wheels into /tmp/site (experiments/device_env.sh);
#   2. generates the small config's dataset (1000 training and 100 test
#      trajectories) into data/small1000 unless one is there, in vmapped
#      batches of GEN_BATCH scenes (default all 1,100: a few compiled
#      programs, one per size bucket);
#   3. trains runs/NAME with configs/small.py and the overrides given,
#      evaluation off, until the run ends or the time left runs out
#      (TRAIN_GPU_BUDGET_S, default 540 s from the start, less 40 s for
#      packing); a run stopped there keeps its checkpoints of every 500
#      steps, and the same command again resumes it (data/ and runs/ are
#      ignored paths, which a warm machine keeps between commands);
#   4. averages the kept checkpoints AVG_STEPS (default the recipe's
#      32000,34000,36000,38000,40000) into runs/NAME_avg5 once all exist;
#   5. packs into $OUT: NAME_run.tar (the run: config, statistics, metrics,
#      TensorBoard events, its latest checkpoint), NAME_avg5.tar (the mean)
#      and the log.
# Unpack here with `tar -xf FILES_AT/NAME_run.tar -C experiments/runs` (and
# the mean likewise), then evaluate on this machine's test split
# (python -m experiments.evaluate).
# The dataset generated there differs from this machine's by rounding
# (docs/performance.md, "Agreement": 0.05 mm RMS after 599 frames).
set -u
name=${1:?usage: bash experiments/train_gpu.sh NAME [--config.X=Y ...]}
shift
budget=${TRAIN_GPU_BUDGET_S:-540}
avg_steps=${AVG_STEPS:-32000,34000,36000,38000,40000}
out=${OUT:-out/train_gpu}
run=runs/$name
data=data/small1000
config=experiments/configs/small.py
mkdir -p "$out"
log="$out/${name}.log"
source experiments/device_env.sh
{ nvidia-smi --query-gpu=name,memory.total --format=csv,noheader
  python3 -c "import jax; print('jax', jax.__version__, jax.devices())"
} > "$log" 2>&1

if [ ! -f "$data/train.h5" ]; then
  echo "== generate $(date -u +%T)" >> "$log"
  python3 -m experiments.generate_dataset --config=$config --out=$data \
    --workers=1 --batch="${GEN_BATCH:-1100}" >> "$log" 2>&1 \
    || { tail -n 30 "$log"; exit 1; }
fi

left=$((budget - SECONDS - 40))
echo "== train ($left s left) $(date -u +%T)" >> "$log"
rc=0
if [ $left -gt 30 ]; then
  timeout "$left" python3 -m experiments.train --config=$config --data=$data \
    --workdir="$run" --config.eval.every_steps=0 "$@" >> "$log" 2>&1
  rc=$?
  [ $rc -eq 124 ] && echo "== stopped by the time left; resume with the run carried" >> "$log"
fi

steps_dir="$run/checkpoints"
have_all=1
for s in ${avg_steps//,/ }; do [ -d "$steps_dir/$s" ] || have_all=0; done
if [ $have_all -eq 1 ] && [ ! -d "${run}_avg5/checkpoints" ]; then
  echo "== average $avg_steps $(date -u +%T)" >> "$log"
  sources=$(for s in ${avg_steps//,/ }; do printf '%s@%s,' "$run" "$s"; done)
  python3 -m experiments.average_runs --workdirs="${sources%,}" \
    --out="${run}_avg5" >> "$log" 2>&1 || rc=1
fi

latest=$(ls "$steps_dir" 2>/dev/null | grep -E '^[0-9]+$' | sort -n | tail -1)
if [ -n "$latest" ]; then
  tar -C runs -cf "$out/${name}_run.tar" --exclude=trainer.lock \
    --exclude="$name/checkpoints" "$name"
  tar -C runs -rf "$out/${name}_run.tar" "$name/checkpoints/$latest"
fi
[ -d "${run}_avg5/checkpoints" ] && tar -C runs -cf "$out/${name}_avg5.tar" \
  "${name}_avg5"
echo "== packed (latest checkpoint ${latest:-none}) $(date -u +%T)" >> "$log"
grep -v "it/s\]\|step/s\]" "$log" | tail -n 40
tr '\r' '\n' < "$log" | grep "step/s" | tail -n 2
exit $rc
