"""The MPM's grid work follows the sand: cost against the domain's size.

``mpm.simulate`` updates only a window of the grid around the sand
(``grid_window=True``, the default; ``mpm.solver.rollout_windowed``). This
times the same sand in domains of growing area with the window and with the
whole grid, and a paper scene both ways, on this machine's first device, by
``timing``'s rules (compilation apart: each configuration is run once to
compile, then ``repeats`` times; ``SimulationResult.wall_time_s``, which
waits for the device; medians). Every windowed run is checked to equal the
whole grid's positions. docs/performance.md holds the figures.
"""

import dataclasses
import sys
from typing import Any, Callable

import numpy as np

import mpm
from experiments import timing


@dataclasses.dataclass(frozen=True)
class Sizes:
  """What to measure.

  Attributes:
    scales: domain edge multipliers (area x scale^2) of the column scene.
    column_frames: frames of the column runs.
    paper_frames: frames of the paper-scene runs (600 in the paper).
    paper_particles: particles of the paper scene.
    repeats: timed runs per configuration (median reported).
    seed: the paper scene's seed.
  """
  scales: tuple[float, ...] = (1.0, 2.0, 4.0)
  column_frames: int = 300
  paper_frames: int = 600
  paper_particles: int = 1000
  repeats: int = 3
  seed: int = 3


FULL = Sizes()
QUICK = Sizes(scales=(1.0, 2.0), column_frames=21, paper_frames=11,
              paper_particles=200, repeats=1)

# The column: 0.19 x 0.2 m of sand (about 380 particles at 1 cm) on a flat
# floor at the left of a 0.9 x 0.5 m domain, as in issue 28's measurement.
COLUMN_DOMAIN = (0.9, 0.5)


def column_scene(scale: float, num_frames: int) -> mpm.Scene:
  """The column in a domain ``scale`` times as wide and as high."""
  width, height = COLUMN_DOMAIN[0] * scale, COLUMN_DOMAIN[1] * scale
  return mpm.Scene.from_dict({
      "name": f"column_x{scale:g}",
      "domain": {"width": width, "height": height},
      "ramp": {"kind": "polynomial", "coefficients": [0.05]},
      "obstacles": [],
      "granular": {"box": [0.05, 0.05, 0.24, 0.25], "spacing": 0.01},
      "num_frames": num_frames})


def _time(scene: mpm.Scene, window: bool, repeats: int):
  """(the warm-up run, timing.summary of the timed runs' wall seconds)."""
  return timing.self_timed(
      lambda: mpm.simulate(scene, grid_window=window), repeats,
      lambda r: r.wall_time_s)


def _pair(scene: mpm.Scene, repeats: int) -> dict[str, Any]:
  """The scene with and without the window: times, ratio, equality."""
  whole_run, whole = _time(scene, False, repeats)
  window_run, window = _time(scene, True, repeats)
  grid = mpm.setup(scene).spec.shape
  return {
      "scene": scene.name, "grid": list(grid),
      "particles": int(window_run.positions.shape[1]),
      "frames": scene.num_frames,
      "whole_grid": whole, "whole_grid_compile_s": whole_run.compile_time_s,
      "window": window, "window_compile_s": window_run.compile_time_s,
      "window_over_whole": window["median_s"] / whole["median_s"],
      "max_position_difference_m": float(
          np.abs(window_run.positions - whole_run.positions).max()),
  }


def measure(sizes: Sizes, log: Callable[[str], None]) -> dict[str, Any]:
  columns = []
  for scale in sizes.scales:
    row = _pair(column_scene(scale, sizes.column_frames), sizes.repeats)
    columns.append(row)
    log(f"column x{scale:g}: {row}")
  for row in columns:
    row["area"] = (row["grid"][0] * row["grid"][1]) / (
        columns[0]["grid"][0] * columns[0]["grid"][1])
    row["whole_grid_over_smallest"] = (row["whole_grid"]["median_s"] /
                                       columns[0]["whole_grid"]["median_s"])
    row["window_over_smallest"] = (row["window"]["median_s"] /
                                   columns[0]["window"]["median_s"])
  paper = _pair(mpm.sample_scene(sizes.seed,
                                 num_particles=sizes.paper_particles,
                                 num_frames=sizes.paper_frames),
                sizes.repeats)
  log(f"paper scene: {paper}")
  return {"sizes": dataclasses.asdict(sizes), "columns": columns,
          "paper_scene": paper}


def to_markdown(result: dict[str, Any]) -> str:
  env = result["environment"]
  lines = [
      "# The MPM's grid window: cost against the domain's size",
      "",
      f"Command: `{result['command']}`",
      "",
      f"{env['date']}, {env['cpu_count']} CPUs ({env['jax_backend']}), load "
      f"{env['load_average_start'][0]:.1f} at the start and "
      f"{env['load_average_end'][0]:.1f} at the end.",
      "",
      "The same column of sand in domains of growing area, with the grid "
      "window (`mpm.simulate`'s default) and with the whole grid; seconds "
      "per run, compilation excluded, median of "
      f"{result['sizes']['repeats']}.",
      "",
      "| domain | grid nodes | area | whole grid (s) | window (s) | "
      "window / whole | whole / smallest | window / smallest | "
      "max position difference (m) |",
      "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
  ]
  for r in result["columns"]:
    lines.append(
        f"| {r['scene']} | {r['grid'][0]} x {r['grid'][1]} | "
        f"{r['area']:.1f}x | {r['whole_grid']['median_s']:.3f} | "
        f"{r['window']['median_s']:.3f} | "
        f"{r['window_over_whole']:.2f} | {r['whole_grid_over_smallest']:.2f} |"
        f" {r['window_over_smallest']:.2f} | "
        f"{r['max_position_difference_m']:.1e} |")
  p = result["paper_scene"]
  lines += [
      "",
      f"Paper scene ({p['scene']}, {p['particles']} particles, "
      f"{p['frames']} frames, grid {p['grid'][0]} x {p['grid'][1]}): whole "
      f"grid {p['whole_grid']['median_s']:.3f} s, window "
      f"{p['window']['median_s']:.3f} s "
      f"({p['window_over_whole']:.2f}x); compiling "
      f"{p['whole_grid_compile_s']:.1f} s against "
      f"{p['window_compile_s']:.1f} s (the window compiles one "
      "program per size it uses); positions differ by at most "
      f"{p['max_position_difference_m']:.1e} m.",
      "",
  ]
  return "\n".join(lines)


def run_benchmark(out_dir: str, *, quick: bool = False,
                  log: Callable[[str], None] = print) -> dict[str, Any]:
  """Measures, writes ``window_benchmark[_quick].json`` and ``.md``."""
  sizes = QUICK if quick else FULL
  env = timing.environment(quick)
  results = {"environment": env,
             "command": "python -m experiments.benchmarks " + " ".join(
                 sys.argv[1:]),
             **measure(sizes, log)}
  timing.end_environment(env)
  timing.write_results(out_dir, "window_benchmark", quick, results,
                       to_markdown(results))
  return results
