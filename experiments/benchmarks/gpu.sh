#!/usr/bin/env bash
# Every accelerator figure, on a bare accelerator machine, in two commands
# of under 10 minutes on one warm machine (docs/performance.md, "On an
# accelerator"):
#
#   bash experiments/benchmarks/gpu.sh mpm,train       # 350 s at most
#   bash experiments/benchmarks/gpu.sh gns             # 260 s at most
#   bash experiments/benchmarks/gpu.sh                 # all three, 610 s
#
# sent with the ignored .whl/ carried (`make wheels` here first). It installs
# those wheels into /tmp/site (the machine has jax, flax, optax, orbax, h5py,
# absl-py, tqdm and matplotlib but not jraph, jax-md, ml-collections, cma or
# tensorboardX), runs each part in a process of its own under its own time
# limit (GPU_PART_LIMITS_S, seconds, default "mpm=200 gns=260 train=150":
# on an H200 on 2026-11-28 the parts took over 160 s, 247 s and about
# 135 s, compilation included) into out/gpu/, then the report, and copies
# the part files, the report and the log into $OUT. A part writes its file
# after each measurement, so one stopped by its limit keeps what it finished
# (the report marks it partial); the parts after it still run. Rebuild the
# report here from the files that came back: python -m experiments.benchmarks
# --what=gpu --gpu_parts=report --out=DIR.
set -u
parts=${1:-mpm,gns,train}
limits=${GPU_PART_LIMITS_S:-mpm=200 gns=260 train=150}
out=${OUT:-out/gpu_results}
mkdir -p "$out" out/gpu
source experiments/device_env.sh
log="$out/gpu_${parts//,/_}.log"
{ nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv
  python3 -c "import jax, flax; print('jax', jax.__version__, 'flax',
flax.__version__, jax.devices())"; } > "$log" 2>&1
rc=0
for part in ${parts//,/ }; do
  limit=$(tr ' ' '\n' <<< "$limits" | sed -n "s/^$part=//p")
  echo "== $part (limit ${limit:-none} s) $(date -u +%T)" >> "$log"
  timeout "${limit:-600}" python3 -m experiments.benchmarks --what=gpu \
    --gpu_parts="$part" --out=out/gpu >> "$log" 2>&1
  r=$?
  [ $r -eq 124 ] && echo "== $part stopped by its limit" >> "$log"
  [ $r -ne 0 ] && rc=$r
  cp out/gpu/gpu_*.json "$out"/ 2>/dev/null  # back even if the call is cut
done
echo "== report $(date -u +%T)" >> "$log"
python3 -m experiments.benchmarks --what=gpu --gpu_parts=report \
  --out=out/gpu >> "$log" 2>&1 || rc=$?
cp out/gpu/gpu_*.json out/gpu/gpu_benchmark.md "$out"/ 2>/dev/null
tail -n 60 "$log"
exit $rc
