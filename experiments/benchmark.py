"""Benchmarks the MPM solver: ``python -m experiments.benchmark --out=DIR``.

Measures microseconds per substep and seconds per 600-frame trajectory of the
paper scene, cost against particle and obstacle count, vmapped batch
throughput, and a Taichi (CPU) peer of the same physics, timed in the same run
and checked against the JAX solver (see ``experiments/mpm_benchmark.py``).
Writes ``mpm_benchmark.json`` and ``mpm_benchmark.md`` (``*_quick.*`` with
``--quick``) to ``--out`` and prints the tables.

The peer needs the optional dependency: ``pip install -e .[bench]``.
"""

from absl import app
from absl import flags
from absl import logging

from experiments import mpm_benchmark

_OUT = flags.DEFINE_string("out", "docs/benchmarks",
                           "Directory for the JSON and Markdown results.")
_QUICK = flags.DEFINE_bool("quick", False,
                           "Tiny sizes (seconds): a smoke test, not figures.")
_TAICHI = flags.DEFINE_bool("taichi", True,
                            "Run the Taichi peer (skipped if not installed).")
_TAICHI_THREADS = flags.DEFINE_integer(
    "taichi_threads", 0, "CPU threads for Taichi; 0: all cores.")


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"unexpected arguments: {argv[1:]}")
  results = mpm_benchmark.run_benchmark(
      _OUT.value, quick=_QUICK.value, taichi=_TAICHI.value,
      taichi_threads=_TAICHI_THREADS.value or None, log=logging.info)
  print(results["markdown"])
  print("Wrote " + ", ".join(results["files"]))


if __name__ == "__main__":
  app.run(main)
