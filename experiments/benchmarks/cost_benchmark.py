"""What the MPM pays for: the domain, and the largest scene of a batch.

``mpm.simulate`` updates only a window of the grid around the sand
(``grid_window=True``, the default; ``mpm.solver.rollout_windowed``), and
``mpm.simulate_batch`` runs scenes of similar size together
(``size_buckets``). This times, on this machine's first device:

1. the same sand in domains of growing area, with the window and with the
   whole grid, and a paper scene both ways (every windowed run checked
   against the whole grid's positions);
2. the speed/accuracy study's scenes one at a time, as one padded batch and
   in size buckets (per trajectory);
3. a scene that rests for its last 40% of frames, stepped to the end and
   stopped at rest (``rest_speed``): the time and the last frame's
   difference.

``timing``'s rules: compilation apart (each configuration is run once to
compile, then ``repeats`` times), ``SimulationResult.wall_time_s``, which
waits for the device, medians. docs/performance.md holds the figures.
"""

import dataclasses
import sys
from typing import Any, Callable

import numpy as np

import mpm
from experiments import timing
from mpm import dataset
from mpm import resolution
from mpm import window


@dataclasses.dataclass(frozen=True)
class Sizes:
  """What to measure.

  Attributes:
    scales: domain edge multipliers (area x scale^2) of the column scene.
    column_frames: frames of the column runs.
    paper_frames: frames of the paper-scene runs (600 in the paper).
    paper_particles: particles of the paper scene.
    paper_fine_spacing: the paper scene again at this particle spacing (m;
      the tradeoff study's reference), a grid large enough to window.
    repeats: timed runs per configuration (median reported).
    seed: the paper scene's seed.
    batch_scenes: scenes of the study's test plan in the batch rows.
    batch_spacing: their particle spacing (m).
    rest_frames: frames of the avalanche stopped at rest (the first
      test-plan scene without obstacles, at ``batch_spacing``; at
      rest_speed 5 mm/s it stops at frame 600, while its surface creeps).
    pour_frames: frames of ``pour_scene`` (at ``batch_spacing``; it rests
      from about frame 350).
    rest_speed: the stop's speed threshold (m/s).
  """
  scales: tuple[float, ...] = (1.0, 2.0, 4.0)
  column_frames: int = 300
  paper_frames: int = 600
  paper_particles: int = 1000
  paper_fine_spacing: float = 0.0025
  repeats: int = 3
  seed: int = 3
  batch_scenes: int = 14
  batch_spacing: float = 0.005
  rest_frames: int = 1000
  pour_frames: int = 600
  rest_speed: float = 0.005


FULL = Sizes()
QUICK = Sizes(scales=(1.0, 2.0), column_frames=21, paper_frames=11,
              paper_particles=200, paper_fine_spacing=0.01, repeats=1,
              batch_scenes=3,
              batch_spacing=0.02, rest_frames=121, pour_frames=121,
              rest_speed=10.0)

# The column: 0.19 x 0.2 m of sand (about 380 particles at 1 cm) on a flat
# floor at the left of a 0.9 x 0.5 m domain, grid spacing 1 cm, as in
# issue 28's measurement.
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
      "solver": {"dx": 0.01},
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
  scene = mpm.sample_scene(sizes.seed, num_particles=sizes.paper_particles,
                           num_frames=sizes.paper_frames)
  paper = [_pair(scene, sizes.repeats),
           _pair(resolution.at_spacing(scene, sizes.paper_fine_spacing),
                 sizes.repeats)]
  log(f"paper scene: {paper}")
  batches = measure_batches(sizes)
  log(f"batches: {batches}")
  rest = measure_rest(sizes)
  log(f"rest: {rest}")
  return {"sizes": dataclasses.asdict(sizes), "columns": columns,
          "paper_scene": paper, "batches": batches, "rest": rest}


def pour_scene(num_frames: int, spacing: float) -> mpm.Scene:
  """Sand that comes to rest: a 6 cm layer dropped 15 cm into a 0.4 m box,
  wall to wall, so that no free slope is left to creep (the avalanche
  scenes' surfaces do: docs/performance.md, "Stopping at rest")."""
  return mpm.Scene.from_dict({
      "name": "pour", "domain": {"width": 0.4, "height": 0.4},
      "ramp": {"kind": "polynomial", "coefficients": [0.05]},
      "obstacles": [],
      "granular": {"box": [0.0, 0.2, 0.4, 0.26], "spacing": spacing},
      "solver": {"dx": 2 * spacing}, "num_frames": num_frames})


def measure_rest(sizes: Sizes) -> list[dict[str, Any]]:
  """Two scenes stepped to their last frame and stopped at rest (the first
  avalanche of the test plan without obstacles, and ``pour_scene``):
  medians of ``repeats`` after a warm-up, and how far the stop's last frame
  lies from the stepped one's."""
  spec = dataset.DatasetSpec(num_train=1, num_test=7,
                             num_frames=sizes.rest_frames,
                             spacing=dataset.PAPER_SPACING)
  plain = next(p.scene for p in dataset.plan(spec)
               if p.split == "test" and not p.scene.obstacles)
  rows = []
  for scene in (resolution.at_spacing(plain, sizes.batch_spacing),
                pour_scene(sizes.pour_frames, sizes.batch_spacing)):
    full_run, full = timing.self_timed(lambda: mpm.simulate(scene),
                                       sizes.repeats, lambda r: r.wall_time_s)
    rest_run, rest = timing.self_timed(
        lambda: mpm.simulate(scene, rest_speed=sizes.rest_speed),
        sizes.repeats, lambda r: r.wall_time_s)
    last = full_run.positions[-1]
    speed = np.linalg.norm(last - full_run.positions[-41], axis=-1) / (
        40 * scene.frame_dt)
    rows.append({
        "scene": scene.name, "frames": scene.num_frames,
        "particles": int(full_run.positions.shape[1]),
        "rest_speed": sizes.rest_speed, "rest_frame": rest_run.rest_frame,
        "stepped": full, "stopped": rest,
        "stopped_over_stepped": rest["median_s"] / full["median_s"],
        "last_frame_difference_m": float(np.abs(
            rest_run.positions[-1] - last).max()),
        "fastest_at_end_m_per_s": float(speed.max())})
  return rows


def measure_batches(sizes: Sizes) -> dict[str, Any]:
  """Seconds per trajectory over the study's scenes: one at a time, one
  padded vmapped batch, vmapped size buckets, and ``simulate_batch``'s
  default (``default_max_batch`` scenes per program; medians of ``repeats``
  rounds after a warm-up, each round running every variant once)."""
  spec = dataset.DatasetSpec(num_train=1, num_test=sizes.batch_scenes,
                             num_frames=sizes.paper_frames,
                             spacing=dataset.PAPER_SPACING)
  scenes = [resolution.at_spacing(p.scene, sizes.batch_spacing)
            for p in dataset.plan(spec) if p.split == "test"]
  per_trajectory = lambda results: sum(
      r.wall_time_s for r in results) / len(results)
  runs = {
      "one_at_a_time": lambda: [mpm.simulate(s) for s in scenes],
      "one_batch": lambda: mpm.simulate_batch(
          scenes, bucket_ratio=None, max_batch=len(scenes)),
      "size_buckets": lambda: mpm.simulate_batch(
          scenes, max_batch=len(scenes)),
      "default": lambda: mpm.simulate_batch(scenes)}
  for run in runs.values():
    run()                                   # compiles
  # Round-robin, so that a load that drifts during the minutes this takes
  # weighs on every variant alike.
  seconds = {name: [] for name in runs}
  for _ in range(sizes.repeats):
    for name, run in runs.items():
      seconds[name].append(per_trajectory(run()))
  rows = {name: timing.summary(s) for name, s in seconds.items()}
  counts = [len(mpm.granular_particles(s)) for s in scenes]
  return {"scenes": len(scenes), "spacing": sizes.batch_spacing,
          "particles": counts,
          "buckets": len(mpm.simulation.size_buckets(counts)),
          "seconds_per_trajectory": rows,
          "one_batch_over_one_at_a_time": (
              rows["one_batch"]["median_s"] /
              rows["one_at_a_time"]["median_s"]),
          "buckets_over_one_at_a_time": (
              rows["size_buckets"]["median_s"] /
              rows["one_at_a_time"]["median_s"]),
          "default_max_batch": mpm.simulation.default_max_batch(),
          "default_over_one_at_a_time": (
              rows["default"]["median_s"] /
              rows["one_at_a_time"]["median_s"])}


def to_markdown(result: dict[str, Any]) -> str:
  env = result["environment"]
  lines = [
      "# What the MPM pays for: the domain and the batch",
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
  lines += [
      "",
      "The paper scene at its own spacing and at the study's reference "
      "spacing (the window runs only on grids of at least "
      f"{window.WINDOW_MIN_NODES:,} nodes):",
      "",
      "| scene | particles | frames | grid nodes | whole grid (s) | window (s)"
      " | window / whole | compile, whole / window (s) | max position "
      "difference (m) |",
      "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
  ]
  for p in result["paper_scene"]:
    lines.append(
        f"| {p['scene']} | {p['particles']} | {p['frames']} | "
        f"{p['grid'][0]} x {p['grid'][1]} | {p['whole_grid']['median_s']:.3f}"
        f" | {p['window']['median_s']:.3f} | {p['window_over_whole']:.2f} | "
        f"{p['whole_grid_compile_s']:.1f} / {p['window_compile_s']:.1f} | "
        f"{p['max_position_difference_m']:.1e} |")
  lines.append("")
  b = result["batches"]
  t = b["seconds_per_trajectory"]
  lines += [
      f"The study's {b['scenes']} test-plan scenes at "
      f"{b['spacing'] * 1e3:g} mm ({min(b['particles'])}-"
      f"{max(b['particles'])} particles), seconds per trajectory: one at a "
      f"time {t['one_at_a_time']['median_s']:.3f}; one batch padded to the "
      f"largest {t['one_batch']['median_s']:.3f} "
      f"({b['one_batch_over_one_at_a_time']:.2f}x); {b['buckets']} size "
      f"buckets {t['size_buckets']['median_s']:.3f} "
      f"({b['buckets_over_one_at_a_time']:.2f}x); `simulate_batch`'s "
      f"default ({b['default_max_batch'] or 'all'} scene(s) per program) "
      f"{t['default']['median_s']:.3f} "
      f"({b['default_over_one_at_a_time']:.2f}x).",
      "",
  ]
  lines += [
      f"Stopping at rest (`rest_speed={result['rest'][0]['rest_speed']:g}`"
      "), against stepping every frame; seconds per run:",
      "",
      "| scene | particles | frames | stopped at frame | stepped (s) | "
      "stopped (s) | stopped / stepped | last frame, largest difference "
      "(mm) | fastest particle at the end, stepped (mm/s) |",
      "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
  ]
  for r in result["rest"]:
    lines.append(
        f"| {r['scene']} | {r['particles']} | {r['frames']} | "
        f"{'never' if r['rest_frame'] is None else r['rest_frame']} | "
        f"{r['stepped']['median_s']:.3f} | {r['stopped']['median_s']:.3f} | "
        f"{r['stopped_over_stepped']:.2f} | "
        f"{r['last_frame_difference_m'] * 1e3:.2f} | "
        f"{r['fastest_at_end_m_per_s'] * 1e3:.2f} |")
  lines.append("")
  return "\n".join(lines)


def run_benchmark(out_dir: str, *, quick: bool = False,
                  log: Callable[[str], None] = print) -> dict[str, Any]:
  """Measures, writes ``cost_benchmark[_quick].json`` and ``.md``."""
  sizes = QUICK if quick else FULL
  env = timing.environment(quick)
  results = {"environment": env,
             "command": "python -m experiments.benchmarks " + " ".join(
                 sys.argv[1:]),
             **measure(sizes, log)}
  timing.end_environment(env)
  timing.write_results(out_dir, "cost_benchmark", quick, results,
                       to_markdown(results))
  return results
