"""Dataset benchmark: generation throughput and reading speed.

  python -m experiments.benchmarks --what=dataset --out=docs/benchmarks \
      --read_data=data/small

``run_benchmark(out_dir)`` measures, in one run on this machine:

1. the wall time to generate 20 paper trajectories (16 training, 4 test
   scenes of the paper's plan, 600 frames) with 1 and with 2 worker
   processes, compilation included (it is part of generating), and the
   extrapolation to the paper's 1100;
2. windows read per second from a dataset file (random access, the training
   path) and padded batches assembled per second, as training assembles
   them (``gnsjax.batching.make_batch``: nodes, padding and each window's
   SDF grid at R / 6, the configs' default ``model.sdf_spacing``).

Writes ``dataset_benchmark.json`` and ``.md`` to ``out_dir``.
"""

import os
import tempfile

from experiments import timing
from gnsjax import batching
from gnsjax import data
from gnsjax import graph
from mpm import dataset
from mpm import io as mpm_io

PAPER_TOTAL = 1100


def time_generation(spec: dataset.DatasetSpec, workers: int,
                    cache: str | None) -> dict:
  """Generates ``spec`` into a temporary directory with ``workers``
  processes; seconds (wall, simulation, fixed), bytes written and the
  extrapolations to the paper's 1100 trajectories (minutes)."""
  with tempfile.TemporaryDirectory() as d:
    # Timed whole: start-up and compilation are part of generating.
    meta, wall = timing.wall(lambda: dataset.generate(
        spec, d, workers=workers, compilation_cache=cache))
    size = sum(os.path.getsize(os.path.join(d, f)) for f in os.listdir(d))
  n = spec.num_train + spec.num_test
  simulation = meta["wall_time_s"]["train"] + meta["wall_time_s"]["test"]
  # Fixed costs (process start, compilation, assembly) do not grow with the
  # dataset; the simulation time per trajectory does, divided by the workers.
  fixed = max(wall - simulation / workers, 0.0)
  return {"workers": workers, "trajectories": n, "wall_s": wall,
          "simulation_s": simulation, "fixed_s": fixed, "bytes": size,
          "extrapolated_1100_min": wall / n * PAPER_TOTAL / 60,
          "steady_1100_min": (fixed + simulation / n * PAPER_TOTAL / workers)
                             / 60}


def time_reading(data_dir: str, windows: int = 2000, batch_size: int = 2,
                 batches: int = 200) -> dict:
  """Windows per second read from the training split of ``data_dir``, and
  padded batches of ``batch_size`` windows assembled per second (with their
  SDF grids at R / 6, cached per scene as in training)."""
  path = data.split_path(data_dir, "train")
  header = mpm_io.read_header(path)
  radius = float(header["connectivity_radius"])
  spec = graph.GraphSpec(radius, tuple(map(tuple, header["bounds"])))
  with data.WindowDataset(path, seed=0) as ds:
    def read():
      for k in range(windows):
        ds[k]

    def assemble():
      for b in range(batches):
        batching.make_batch([ds[b * batch_size + i]
                             for i in range(batch_size)], spec,
                            sdf_spacing=radius / 6)

    ds[0]  # warm-up: opens the file
    _, read_s = timing.wall(read)
    _, batch_s = timing.wall(assemble)
  return {"windows_per_s": windows / read_s,
          "batches_per_s": batches / batch_s, "batch_size": batch_size}


def run_benchmark(out_dir: str, read_data: str | None = None,
                  quick: bool = False, cache: str | None = None,
                  log=print) -> dict:
  """Measures generation and reading; writes JSON and Markdown."""
  spec = dataset.DatasetSpec(num_train=2 if quick else 16,
                             num_test=1 if quick else 4,
                             num_frames=20 if quick else 600,
                             spacing=0.01 if quick else 0.005)
  env = timing.environment(quick)
  results = {"environment": env, "spec": dict(spec.__dict__),
             "generation": []}
  for workers in (2, 1):
    r = time_generation(spec, workers, cache)
    log(f"generate {r['trajectories']} trajectories with {workers} "
        f"worker(s): {r['wall_s']:.1f} s -> 1100 in "
        f"{r['extrapolated_1100_min']:.1f} min")
    results["generation"].append(r)
  if read_data:
    results["reading"] = time_reading(read_data, 200 if quick else 2000,
                                      batches=20 if quick else 200)
    log(f"reading: {results['reading']['windows_per_s']:.0f} windows/s, "
        f"{results['reading']['batches_per_s']:.0f} batches/s")
  g2, g1 = results["generation"]
  lines = [
      "## Dataset generation and reading", "",
      f"{env['date']}, {env['machine']}, {env['cpu_count']} CPUs, load "
      f"{env['load_average_start'][0]:.1f} at the start.", "",
      "| workers | trajectories | wall (s) | simulation (s) | fixed (s) | "
      "1100, wall x 55 (min) | 1100, fixed + simulation (min) |",
      "|---|---|---|---|---|---|---|"]
  for r in results["generation"]:
    lines.append(f"| {r['workers']} | {r['trajectories']} | {r['wall_s']:.1f}"
                 f" | {r['simulation_s']:.1f} | {r['fixed_s']:.1f} | "
                 f"{r['extrapolated_1100_min']:.1f} | "
                 f"{r['steady_1100_min']:.1f} |")
  lines += ["", f"Two workers vs one: {g1['wall_s'] / g2['wall_s']:.2f}x "
            "faster on 20 trajectories, where process start-up and "
            "compilation ('fixed') weigh heavily. Simulation time is the sum "
            "of the trajectories' `wall_time_s`; 'fixed' is wall time minus "
            "simulation time / workers. The last column scales only the "
            "simulation time to 1100 trajectories."]
  if "reading" in results:
    r = results["reading"]
    lines += ["", f"Reading `{read_data}`: {r['windows_per_s']:.0f} random "
              f"windows/s; {r['batches_per_s']:.0f} padded batches of "
              f"{r['batch_size']} windows/s."]
  timing.end_environment(env)
  timing.write_results(out_dir, "dataset_benchmark", quick, results,
                       "\n".join(lines) + "\n")
  return results
