"""Benchmarks the MPM solver and the GNS: ``python -m experiments.benchmarks``.

``--what=mpm,gns`` (default both) picks the benchmarks; each writes JSON and
Markdown to ``--out`` (``*_quick.*`` with ``--quick``) and prints its tables.

mpm (``experiments/benchmarks/mpm_benchmark.py``): microseconds per substep and seconds
per 600-frame trajectory of the paper scene, cost against particle and
obstacle count, vmapped batch throughput, and a Taichi (CPU) peer of the same
physics, timed in the same run and checked against the JAX solver. Writes
``mpm_benchmark.json`` and ``mpm_benchmark.md``. The peer needs the optional
dependency: ``pip install -e .[bench]``.

gns (``experiments/benchmarks/gns_benchmark.py``): forward and training step of the
paper and small models on the shared sand block window and on the paper
scene, against the quoted geoelements/gns and LagrangeBench times, the
achieved FLOP rate against this machine's matmul rate, and the split first
edge layer against the concatenated form. Writes ``gns_benchmark.json`` and
``gns_benchmark.md``.

dataset (``experiments/benchmarks/dataset_benchmark.py``): wall time to generate 20 paper
trajectories with 2 and 1 worker processes, extrapolated to the paper's 1100,
and windows and padded batches read per second from ``--read_data``. Writes
``dataset_benchmark.json`` and ``dataset_benchmark.md``.

design (``experiments/benchmarks/design_benchmark.py``): the gradient of an objective
w.r.t. an obstacle's x against the forward rollout, for MPM and GNS, time
ratio and XLA memory. Writes ``design_benchmark.json`` and
``design_benchmark.md``.
"""

from absl import app
from absl import flags
from absl import logging

from experiments.benchmarks import dataset_benchmark
from experiments.benchmarks import design_benchmark
from experiments.benchmarks import gns_benchmark
from experiments.benchmarks import mpm_benchmark
from experiments import runtime

_BENCHMARKS = ("mpm", "gns", "dataset", "design")

_OUT = flags.DEFINE_string("out", "docs/benchmarks",
                           "Directory for the JSON and Markdown results.")
_WHAT = flags.DEFINE_list("what", ["mpm", "gns"],
                          "Benchmarks to run, comma-separated: mpm, gns, "
                          "dataset, design.")
_QUICK = flags.DEFINE_bool("quick", False,
                           "Tiny sizes (seconds): a smoke test, not figures.")
_TAICHI = flags.DEFINE_bool("taichi", True,
                            "mpm: run the Taichi peer (skipped if not "
                            "installed).")
_TAICHI_THREADS = flags.DEFINE_integer(
    "taichi_threads", 0, "mpm: CPU threads for Taichi; 0: all cores.")
_SAND_BLOCK_DIR = flags.DEFINE_string(
    "sand_block_dir", gns_benchmark.SAND_BLOCK_DIR,
    "gns: directory of sand_block_window.npz and sand_block_metadata.json.")

_READ_DATA = flags.DEFINE_string(
    "read_data", None, "dataset: a dataset directory to time reading on.")

flags.register_validator(
    "what", lambda v: bool(v) and set(v) <= set(_BENCHMARKS),
    message=f"--what takes a comma-separated subset of {list(_BENCHMARKS)}")


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"unexpected arguments: {argv[1:]}")
  what = _WHAT.value
  if "mpm" in what:
    results = mpm_benchmark.run_benchmark(
        _OUT.value, quick=_QUICK.value, taichi=_TAICHI.value,
        taichi_threads=_TAICHI_THREADS.value or None, log=logging.info)
    print(results["markdown"])
    print("Wrote " + ", ".join(results["files"]))
  if "gns" in what:
    results = gns_benchmark.run_benchmark(
        _OUT.value, quick=_QUICK.value, log=logging.info,
        sand_block_dir=_SAND_BLOCK_DIR.value)
    print(results["markdown"])
    print("Wrote " + ", ".join(results["files"]))
  if "dataset" in what:
    results = dataset_benchmark.run_benchmark(
        _OUT.value, read_data=_READ_DATA.value, quick=_QUICK.value,
        cache=runtime.enable_compilation_cache(), log=logging.info)
    print(results["markdown"])
  if "design" in what:
    results = design_benchmark.run_benchmark(_OUT.value, quick=_QUICK.value,
                                             log=logging.info)
    print(results["markdown"])
    print("Wrote " + ", ".join(results["files"]))


if __name__ == "__main__":
  app.run(main)
