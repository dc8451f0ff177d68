"""How every benchmark and study times, records its machine and writes
its results.

The rules (docs/performance.md) in one place:

* compilation is timed apart (:func:`compile_program`) and never counted in a
  figure; one warm-up call is made and not counted either;
* the clock stops after ``jax.block_until_ready`` of the call's result (a
  peer's call waits for its own work, e.g. Taichi's ``ti.sync()``);
* each figure is the median of repeats, the minimum beside it;
* calls compared with each other are interleaved, one call of each per round
  (:func:`time_calls`), so that load from other processes falls on all of
  them alike;
* each result records the machine, the software and the load average
  (:func:`environment`), and is written atomically (:func:`write_results`),
  so that an interrupted run never leaves half a file in ``docs/``.

Times are seconds unless a key says otherwise (``*_us``: microseconds).
"""

import dataclasses
import datetime
import json
import os
import platform
import statistics
import time
from typing import Any, Callable, Mapping, Sequence

import jax
import numpy as np

from mpm import io as mpm_io


# ------------------------------------------------------------ timing ---


def summary(seconds: Sequence[float]) -> dict[str, Any]:
  """Median, minimum and every sample of repeated timings (s)."""
  return {"median_s": statistics.median(seconds), "min_s": min(seconds),
          "repeats": len(seconds), "all_s": list(seconds)}


def per_unit_us(timing: Mapping[str, Any], units: int) -> dict[str, Any]:
  """A :func:`summary` per unit of work (e.g. one substep), in us."""
  per = [s / units * 1e6 for s in timing["all_s"]]
  return {"median_us": statistics.median(per), "min_us": min(per),
          "repeats": len(per), "units_per_repeat": units}


def time_calls(calls: Mapping[str, Callable[[], Any]], repeats: int, *,
               prepare: Mapping[str, Callable[[], Any]] | None = None
               ) -> dict[str, dict[str, Any]]:
  """Seconds per call of each zero-argument function, interleaved.

  Each function is called once to warm up (``warmup_s``: that call's time,
  compilation included if it compiles), then the functions take turns,
  ``repeats`` rounds, so that load from other processes falls on all of them
  alike. The clock stops after ``jax.block_until_ready`` of the result.

  Args:
    calls: name -> function to time.
    repeats: timed calls of each function.
    prepare: name -> function run before each call of that name (the warm-up
      included), outside the clock: e.g. putting a peer back to its initial
      state, so that every repeat does the same work.

  Returns:
    name -> :func:`summary` of its timed calls, with ``warmup_s``.
  """
  prepare = prepare or {}
  nothing = lambda: None

  def timed(name):
    prepare.get(name, nothing)()
    start = time.perf_counter()
    jax.block_until_ready(calls[name]())
    return time.perf_counter() - start

  warmup = {name: timed(name) for name in calls}
  seconds = {name: [] for name in calls}
  for _ in range(repeats):
    for name in calls:
      seconds[name].append(timed(name))
  return {name: {**summary(s), "warmup_s": warmup[name]}
          for name, s in seconds.items()}


def self_timed(run: Callable[[], Any], repeats: int,
               seconds: Callable[[Any], float]) -> tuple[Any, dict[str, Any]]:
  """Repeats of a call that times itself, after one warm-up call.

  For the library's own clocks (``mpm.simulate``'s ``wall_time_s``, which
  already excludes compilation and waits for the device): the figure is
  what a user of that call sees.

  Args:
    run: the call.
    repeats: timed calls after the warm-up.
    seconds: the seconds a result reports.

  Returns:
    (the warm-up call's result, :func:`summary` of the timed calls).
  """
  first = run()
  return first, summary([seconds(run()) for _ in range(repeats)])


def wall(fn: Callable[[], Any]) -> tuple[Any, float]:
  """(result, seconds) of one call timed whole, start-up and compilation
  included: for work whose cost is all of it (generating a dataset)."""
  start = time.perf_counter()
  result = jax.block_until_ready(fn())
  return result, time.perf_counter() - start


@dataclasses.dataclass(frozen=True)
class Compiled:
  """A compiled program and what compiling it told.

  Attributes:
    executable: the ``jax.stages.Compiled``; call it with the non-static
      arguments.
    compile_s: seconds to lower and compile.
    flops: XLA's cost analysis of the program (None where it has none).
  """
  executable: Any
  compile_s: float
  flops: float | None

  def __call__(self, *args):
    return self.executable(*args)


def compile_program(fn, *args, **static) -> Compiled:
  """Lowers and compiles a ``jax.jit``-ed ``fn`` for ``args``, timed apart.

  ``static`` holds the keyword arguments ``fn`` marks static.
  """
  start = time.perf_counter()
  executable = fn.lower(*args, **static).compile()
  compile_s = time.perf_counter() - start
  cost = executable.cost_analysis()
  cost = cost[0] if isinstance(cost, (list, tuple)) else cost
  flops = float(cost["flops"]) if cost and "flops" in cost else None
  return Compiled(executable, compile_s, flops)


# ------------------------------------------------------------ record ---


def environment(quick: bool, **extra) -> dict[str, Any]:
  """Date, machine, software and load at the start of a benchmark."""
  return {
      "date": datetime.datetime.now(datetime.timezone.utc).isoformat(
          timespec="seconds"),
      "quick": quick,
      "python": platform.python_version(),
      "machine": platform.machine(), "platform": platform.platform(),
      "cpu_count": os.cpu_count(),
      "jax_version": jax.__version__,
      "jax_backend": jax.default_backend(),
      "jax_devices": [str(d) for d in jax.devices()],
      "xla_flags": os.environ.get("XLA_FLAGS", ""),
      "load_average_start": list(os.getloadavg()),
      **extra,
  }


def end_environment(env: dict[str, Any]) -> None:
  """Adds the load average at the end of the benchmark to ``env``."""
  env["load_average_end"] = list(os.getloadavg())


# ------------------------------------------------------------ output ---


def _json_default(v):
  if isinstance(v, (np.floating, np.integer, np.bool_)):
    return v.item()
  if isinstance(v, np.ndarray):
    return v.tolist()
  raise TypeError(f"not JSON serialisable: {type(v)}")


def write_json(path: str, content: Any) -> None:
  """Writes ``content`` as indented JSON (numpy values as numbers) to
  ``path``, atomically."""
  mpm_io.write_text(path, json.dumps(content, indent=1,
                                     default=_json_default) + "\n")


def write_results(out_dir: str, name: str, quick: bool,
                  results: dict[str, Any], markdown: str) -> list[str]:
  """Writes ``<name>[_quick].json`` and ``.md`` to ``out_dir`` (created).

  Sets ``results["markdown"]`` and ``results["files"]`` (neither goes into
  the JSON) and returns the files written.
  """
  os.makedirs(out_dir, exist_ok=True)
  stem = os.path.join(out_dir, name + ("_quick" if quick else ""))
  content = {k: v for k, v in results.items()
             if k not in ("markdown", "files")}
  mpm_io.write_text(stem + ".json",
               json.dumps(content, indent=1, default=_json_default) + "\n")
  mpm_io.write_text(stem + ".md", markdown)
  results["markdown"] = markdown
  results["files"] = [stem + ".json", stem + ".md"]
  return results["files"]
