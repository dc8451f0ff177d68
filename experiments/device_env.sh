# Sourced by the commands sent to a lent accelerator machine
# (experiments/benchmarks/gpu.sh, experiments/train_gpu.sh), from the
# repository root: installs the carried wheels (.whl/, `make wheels`: the
# pure-Python packages that machine lacks) into /tmp/site, puts it and the
# repository on PYTHONPATH, and keeps compiled programs in .jax_cache/gpu.
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir \
  --upgrade --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH="/tmp/site:$PWD:${PYTHONPATH:-}"
export JAX_COMPILATION_CACHE_DIR="$PWD/.jax_cache/gpu"
