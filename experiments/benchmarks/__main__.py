"""Runs the benchmarks: ``python -m experiments.benchmarks --what=...``.

  python -m experiments.benchmarks --what=mpm --out=docs/benchmarks
  python -m experiments.benchmarks --what=gns --out=docs/benchmarks \\
      --sand_block_dir=DIR
  python -m experiments.benchmarks --what=dataset --out=docs/benchmarks \\
      --read_data=data/small
  python -m experiments.benchmarks --what=design --out=docs/benchmarks
  python -m experiments.benchmarks --what=batch --out=docs/benchmarks
  python -m experiments.benchmarks --what=mpm,gns --quick ...   # smoke test

``--what`` (comma-separated; default mpm,gns) picks the benchmarks; each
writes ``<name>_benchmark.json`` and ``.md`` to ``--out`` (``*_quick.*``
with ``--quick``, tiny sizes that are not figures) and prints its tables.
What each measures is in the package docstring (``__init__.py``). The gns
benchmark needs the shared sand block window, which is not part of the
repository: ``--sand_block_dir``.
"""

import os

from absl import app
from absl import flags
from absl import logging

from experiments import runtime
from experiments.benchmarks import batch_benchmark
from experiments.benchmarks import dataset_benchmark
from experiments.benchmarks import design_benchmark
from experiments.benchmarks import gns_benchmark
from experiments.benchmarks import gns_inputs
from experiments.benchmarks import input_benchmark
from experiments.benchmarks import mpm_benchmark

BENCHMARKS = ("mpm", "gns", "dataset", "design", "input", "batch")

_OUT = flags.DEFINE_string("out", "docs/benchmarks",
                           "Directory for the JSON and Markdown results.")
_WHAT = flags.DEFINE_list("what", ["mpm", "gns"],
                          "Benchmarks to run, comma-separated subset of "
                          f"{', '.join(BENCHMARKS)}.")
_QUICK = flags.DEFINE_bool("quick", False,
                           "Tiny sizes (seconds): a smoke test, not figures.")
_TAICHI = flags.DEFINE_bool("taichi", True,
                            "mpm: run the Taichi peer (skipped if not "
                            "installed).")
_TAICHI_THREADS = flags.DEFINE_integer(
    "taichi_threads", 0, "mpm: CPU threads for Taichi; 0: all cores.",
    lower_bound=0)
_SAND_BLOCK_DIR = flags.DEFINE_string(
    "sand_block_dir", None,
    "gns (required): directory of the shared sand block window, "
    f"{gns_inputs.SAND_BLOCK_NPZ} and {gns_inputs.SAND_BLOCK_METADATA} "
    f"(and the {gns_inputs.SAND_BLOCK_README} quoting the peers' times).")
_READ_DATA = flags.DEFINE_string(
    "read_data", None, "dataset, input: a dataset directory to time reading "
    "on (input: required, a dataset of the small config).")


def _check_what(value: list[str]) -> bool:
  unknown = [v for v in value if v not in BENCHMARKS]
  if not value or unknown:
    raise flags.ValidationError(
        f"--what={','.join(value)}: unknown {unknown or 'empty'}; allowed: "
        f"a comma-separated subset of {list(BENCHMARKS)}")
  return True


flags.register_validator("what", _check_what)


def check_inputs(what: list[str]) -> None:
  """Fails before any timing if a chosen benchmark lacks its input.

  Raises:
    app.UsageError: naming the flag, its value and what it needs.
  """
  if "gns" in what:
    if not _SAND_BLOCK_DIR.value:
      raise app.UsageError(
          "--sand_block_dir is required with --what=gns: the directory of "
          f"{gns_inputs.SAND_BLOCK_NPZ} and "
          f"{gns_inputs.SAND_BLOCK_METADATA} (the shared sand block "
          "window, not part of the repository); or leave gns out of --what")
    try:
      gns_inputs.sand_block_files(_SAND_BLOCK_DIR.value)
    except FileNotFoundError as e:
      raise app.UsageError(f"--sand_block_dir={_SAND_BLOCK_DIR.value}: "
                           f"{e}") from e
  if "input" in what and _READ_DATA.value is None:
    raise app.UsageError("--read_data is required with --what=input: a "
                         "dataset directory of the small config")
  if _READ_DATA.value is not None:
    if "dataset" not in what and "input" not in what:
      raise app.UsageError(f"--read_data={_READ_DATA.value}: only used by "
                           "--what=dataset or input (got "
                           f"--what={','.join(what)})")
    if not os.path.isdir(_READ_DATA.value):
      raise app.UsageError(f"--read_data={_READ_DATA.value}: not a "
                           "directory (a dataset written by "
                           "experiments.generate_dataset)")


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"unexpected arguments: {argv[1:]}")
  what = _WHAT.value
  check_inputs(what)
  runtime.writable("out", _OUT.value)
  out, quick = _OUT.value, _QUICK.value
  runs = {
      "mpm": lambda: mpm_benchmark.run_benchmark(
          out, quick=quick, taichi=_TAICHI.value,
          taichi_threads=_TAICHI_THREADS.value or None, log=logging.info),
      "gns": lambda: gns_benchmark.run_benchmark(
          out, _SAND_BLOCK_DIR.value, quick=quick, log=logging.info),
      # The dataset's workers are processes: they share compiled programs
      # only through the on-disk cache.
      "dataset": lambda: dataset_benchmark.run_benchmark(
          out, read_data=_READ_DATA.value, quick=quick,
          cache=runtime.enable_compilation_cache(), log=logging.info),
      "design": lambda: design_benchmark.run_benchmark(
          out, quick=quick, log=logging.info),
      "input": lambda: input_benchmark.run_benchmark(
          _READ_DATA.value, out, quick=quick),
      "batch": lambda: batch_benchmark.run_benchmark(
          out, quick=quick, log=logging.info),
  }
  for name in BENCHMARKS:
    if name in what:
      results = runs[name]()
      print(results["markdown"])
      print("Wrote " + ", ".join(results["files"]))


if __name__ == "__main__":
  runtime.run(main)
