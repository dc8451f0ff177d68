"""Runs the benchmarks: ``python -m experiments.benchmarks --what=...``.

  python -m experiments.benchmarks --what=mpm --out=docs/benchmarks
  python -m experiments.benchmarks --what=gns --out=docs/benchmarks \\
      --sand_block_dir=DIR
  python -m experiments.benchmarks --what=dataset --out=docs/benchmarks \\
      --read_data=data/small
  python -m experiments.benchmarks --what=design --out=docs/benchmarks
  python -m experiments.benchmarks --what=batch --out=docs/benchmarks
  python -m experiments.benchmarks --what=cost --out=docs/benchmarks
  python -m experiments.benchmarks --what=gpu --out=DIR \\
      [--gpu_parts=mpm,gns,train] [--cpu_reference=FILE]
  python -m experiments.benchmarks --what=mpm,gns --quick ...   # smoke test

``--what`` (comma-separated; default mpm,gns) picks the benchmarks; each
writes ``<name>_benchmark.json`` and ``.md`` to ``--out`` (``*_quick.*``
with ``--quick``, tiny sizes that are not figures) and prints its tables.
What each measures is in the package docstring (``__init__.py``). The gns
benchmark needs the shared sand block window, which is not part of the
repository: ``--sand_block_dir``.

gpu (``gpu_benchmark``) measures on the first device: on an accelerator it
writes ``gpu_<part>.json`` per part and ``gpu_benchmark.{json,md}``, with
the CPU reference (``--cpu_reference``) beside every figure; on the CPU it
measures that reference (``gpu_cpu_<part>.json``,
``gpu_cpu_reference.{json,md}``). ``--gpu_parts=report`` measures nothing
and rebuilds the report from the part files in ``--out``. On an
accelerator machine run it through ``experiments/benchmarks/gpu.sh``
(docs/performance.md).
"""

import os
import sys

from absl import app
from absl import flags
from absl import logging

from experiments import runtime
from experiments.benchmarks import batch_benchmark
from experiments.benchmarks import dataset_benchmark
from experiments.benchmarks import design_benchmark
from experiments.benchmarks import gns_benchmark
from experiments.benchmarks import gns_inputs
from experiments.benchmarks import gpu_benchmark
from experiments.benchmarks import input_benchmark
from experiments.benchmarks import mpm_benchmark
from experiments.benchmarks import cost_benchmark

FLAGS = flags.FLAGS
BENCHMARKS = ("mpm", "gns", "dataset", "design", "input", "batch", "cost",
              "gpu")
GPU_PARTS = gpu_benchmark.PARTS + ("report",)

_OUT = flags.DEFINE_string(
    "out", "out/benchmarks", "Directory for the JSON and Markdown results "
    "(--out=docs/benchmarks replaces the committed figures).")
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
_GPU_PARTS = flags.DEFINE_list(
    "gpu_parts", list(gpu_benchmark.PARTS),
    "gpu: parts to measure, a comma-separated subset of "
    f"{', '.join(gpu_benchmark.PARTS)}; or report alone: measure nothing, "
    "rebuild the report from the part files in --out.")
_CPU_REFERENCE = flags.DEFINE_string(
    "cpu_reference", gpu_benchmark.DEFAULT_REFERENCE,
    "gpu, on an accelerator: the CPU reference report whose figures stand "
    "beside this device's (measured by --what=gpu on the CPU).")
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


def _check_gpu_parts(value: list[str]) -> bool:
  unknown = [v for v in value if v not in GPU_PARTS]
  if not value or unknown or ("report" in value and len(value) > 1):
    raise flags.ValidationError(
        f"--gpu_parts={','.join(value)}: "
        + (f"unknown {unknown}" if unknown else "empty" if not value else
           "report goes alone") + "; allowed: a comma-separated subset of "
        f"{list(gpu_benchmark.PARTS)}, or report alone")
  return True


flags.register_validator("gpu_parts", _check_gpu_parts)


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
  elif _SAND_BLOCK_DIR.value is not None:
    raise app.UsageError(f"--sand_block_dir={_SAND_BLOCK_DIR.value}: only "
                         f"used by --what=gns (got --what={','.join(what)})")
  if "input" in what and _READ_DATA.value is None:
    raise app.UsageError("--read_data is required with --what=input: a "
                         "dataset directory of the small config")
  if not FLAGS["gpu_parts"].using_default_value and "gpu" not in what:
    raise app.UsageError(f"--gpu_parts={','.join(_GPU_PARTS.value)}: only "
                         f"used by --what=gpu (got --what={','.join(what)})")
  if not FLAGS["cpu_reference"].using_default_value:
    if "gpu" not in what:
      raise app.UsageError(f"--cpu_reference={_CPU_REFERENCE.value}: only "
                           "used by --what=gpu (got "
                           f"--what={','.join(what)})")
    if not os.path.isfile(_CPU_REFERENCE.value):
      raise app.UsageError(f"--cpu_reference={_CPU_REFERENCE.value}: no such"
                           " file (the report of --what=gpu run on the CPU)")
  if "gpu" in what and _GPU_PARTS.value == ["report"]:
    if not any(gpu_benchmark.read_parts(_OUT.value, role, _QUICK.value)
               for role in (True, False)):
      q = "_quick" if _QUICK.value else ""
      raise app.UsageError(
          f"--gpu_parts=report: no gpu_<part>{q}.json nor gpu_cpu_<part>"
          f"{q}.json in --out={_OUT.value} to report on (measure a part "
          "first)")
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
      "cost": lambda: cost_benchmark.run_benchmark(
          out, quick=quick, log=logging.info),
      "gpu": lambda: (
          gpu_benchmark.report_all(out, quick=quick,
                                   cpu_reference=_CPU_REFERENCE.value)
          if _GPU_PARTS.value == ["report"] else
          [gpu_benchmark.run_benchmark(
              out, quick=quick, log=logging.info, parts=_GPU_PARTS.value,
              cpu_reference=_CPU_REFERENCE.value,
              command="python -m experiments.benchmarks " + " ".join(
                  sys.argv[1:]))]),
  }
  for name in BENCHMARKS:
    if name in what:
      results = runs[name]()
      for r in results if isinstance(results, list) else [results]:
        print(r["markdown"])
        print("Wrote " + ", ".join(r["files"]))


if __name__ == "__main__":
  runtime.run(main)
