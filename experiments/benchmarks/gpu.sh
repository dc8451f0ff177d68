#!/usr/bin/env bash
# Every accelerator figure, on a bare accelerator machine, in two commands of
# under 9 minutes each (docs/performance.md, "On an accelerator"):
#
#   bash experiments/benchmarks/gpu.sh mpm          # the first command
#   bash experiments/benchmarks/gpu.sh gns,train    # the second
#
# sent with the ignored .whl/ carried (`make wheels` here first). It installs
# those wheels into /tmp/site (the machine has jax, flax, optax, orbax, h5py,
# absl-py, tqdm and matplotlib but not jraph, jax-md, ml-collections, cma or
# tensorboardX), runs the parts into out/gpu/ (kept between commands while the
# machine stays warm, so the second report holds every part) and copies the
# part files, the report and the log into $OUT. A part killed by the time
# limit leaves no file; the parts before it stay. Rebuild the report here
# from the files that came back: python -m experiments.benchmarks
# --what=gpu --gpu_parts=report --out=DIR.
set -u
parts=${1:-mpm,gns,train}
out=${OUT:-out/gpu_results}
site=/tmp/site
mkdir -p "$out" out/gpu
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir \
  --upgrade --target "$site" .whl/*.whl || exit 1
export PYTHONPATH="$site:$PWD:${PYTHONPATH:-}"
export JAX_COMPILATION_CACHE_DIR="$PWD/.jax_cache/gpu"
log="$out/gpu_${parts//,/_}.log"
{ nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv
  python3 -c "import jax, flax; print('jax', jax.__version__, 'flax',
flax.__version__, jax.devices())"; } > "$log" 2>&1
timeout "${GPU_BENCH_LIMIT_S:-525}" python3 -m experiments.benchmarks \
  --what=gpu --gpu_parts="$parts" --out=out/gpu >> "$log" 2>&1
rc=$?
cp out/gpu/gpu_*.json out/gpu/gpu_benchmark.md "$out"/ 2>/dev/null
tail -n 40 "$log"
exit $rc
