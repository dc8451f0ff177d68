"""Batched MPM: particle-substeps per second against scenes per batch.

``mpm.simulate_batch`` runs B scenes as one vmapped program. This times it
for growing B on this machine's first device (the rules of ``timing``:
compilation apart, a warm-up run, the library's own clock, which waits for
the device, medians of repeats) and records what ``mpm.batch_sizing.
batch_size_for`` chooses here: from ``memory_stats()`` on an accelerator,
its fallback on the CPU. docs/scaling.md holds the figures.
"""

import dataclasses
import statistics
import sys
from typing import Any, Callable

import jax.numpy as jnp

import mpm
from experiments import timing
from mpm import batch_sizing

# The H100 target of issue #15 (not measurable without a GPU).
TARGET_PARTICLE_SUBSTEPS_PER_S = 1e8


@dataclasses.dataclass(frozen=True)
class Sizes:
  """What to measure.

  Attributes:
    particles: particles per scene (paper spacing 0.005 m).
    batch_sizes: scenes per vmapped call.
    frames: frames per timed call.
    repeats: timed calls per batch size (median reported).
    seed: first seed of the sampled scenes.
  """
  particles: int = 1000
  batch_sizes: tuple[int, ...] = (1, 2, 4, 8, 16)
  frames: int = 2
  repeats: int = 3
  seed: int = 0


FULL = Sizes()
QUICK = Sizes(particles=100, batch_sizes=(1, 2), frames=1, repeats=1)


def _setups(sizes: Sizes, count: int) -> list[mpm.Setup]:
  scenes = [mpm.sample_scene(sizes.seed + i, num_particles=sizes.particles,
                             num_frames=sizes.frames + 1)
            for i in range(count)]
  setups = [mpm.setup(s) for s in scenes]
  # As mpm.simulate_batch: one substep count, the largest any scene needs.
  n_substeps = max(s.n_substeps for s in setups)
  return [dataclasses.replace(s, n_substeps=n_substeps, params=s.params.replace(
      dt=jnp.asarray(s.scene.frame_dt / n_substeps, jnp.float32)))
          for s in setups]


def measure(sizes: Sizes, log: Callable[[str], None]) -> dict[str, Any]:
  """Rows of (batch, seconds per call, particle-substeps per second)."""
  setups = _setups(sizes, max(sizes.batch_sizes))
  n_substeps = setups[0].n_substeps
  rows = []
  for b in sizes.batch_sizes:
    chosen = setups[:b]
    _, seconds = timing.self_timed(
        lambda chosen=chosen: mpm.simulate_setups(chosen,
                                                  chunk_frames=sizes.frames),
        sizes.repeats, lambda results: results[0].wall_time_s * len(results))
    work = sum(s.n_particles for s in chosen) * sizes.frames * n_substeps
    rates = [work / t for t in seconds["all_s"]]
    row = {"batch": b, "particle_substeps": work,
           "median_s": seconds["median_s"], "min_s": seconds["min_s"],
           "repeats": seconds["repeats"],
           "particle_substeps_per_s": statistics.median(rates),
           "particle_substeps_per_s_best": max(rates)}
    rows.append(row)
    log(f"batch {b}: {row['particle_substeps_per_s']:.3g} particle-substeps"
        f"/s (median of {row['repeats']}; {row['median_s']:.3f} s a call)")
  return {"particles_per_scene": sizes.particles, "frames": sizes.frames,
          "n_substeps_per_frame": n_substeps, "rows": rows}


def to_markdown(results: dict[str, Any]) -> str:
  env, m, s = results["environment"], results["measured"], results["sizing"]
  lines = [
      "# Batched MPM throughput" + (" (quick: not figures)"
                                    if env["quick"] else ""),
      "",
      f"Command: `{results['command']}`  ",
      f"Machine: {env['platform']}, {env['cpu_count']} CPUs, JAX "
      f"{env['jax_version']} on {env['jax_backend']} "
      f"({', '.join(env['jax_devices'])}); load average "
      f"{env['load_average_start'][0]:.2f} at the start, "
      f"{env['load_average_end'][0]:.2f} at the end.",
      "",
      f"{m['particles_per_scene']} particles per scene, {m['frames']} frames "
      f"of {m['n_substeps_per_frame']} substeps per call; compilation "
      "excluded, one warm-up call, medians of repeats.",
      "",
      "| scenes per batch | s per call | particle-substeps/s (median) | best |",
      "|---|---|---|---|",
  ]
  for r in m["rows"]:
    lines.append(f"| {r['batch']} | {r['median_s']:.3f} | "
                 f"{r['particle_substeps_per_s']:.3g} | "
                 f"{r['particle_substeps_per_s_best']:.3g} |")
  lines += [
      "",
      f"`batch_size_for` here: {s['batch']} scenes ({s['source']}); "
      f"per-scene footprint {s['per_scene_bytes'] / 2**20:.2f} MiB, fixed "
      f"{s['fixed_bytes'] / 2**20:.2f} MiB.",
      "",
      f"Target on an H100: {TARGET_PARTICLE_SUBSTEPS_PER_S:.0e} "
      "particle-substeps/s" + (
          "; not measured: no GPU was available."
          if env["jax_backend"] == "cpu" else "."),
      "",
  ]
  return "\n".join(lines)


def run_benchmark(out_dir: str, *, quick: bool = False,
                  log: Callable[[str], None] = print) -> dict[str, Any]:
  """Measures, writes ``batch_benchmark[_quick].json`` and ``.md``."""
  sizes = QUICK if quick else FULL
  env = timing.environment(quick)
  scene = mpm.sample_scene(sizes.seed, num_particles=sizes.particles,
                           num_frames=sizes.frames + 1)
  sizing = batch_sizing.batch_size_for(scene, chunk_frames=sizes.frames)
  log(f"batch_size_for: {sizing}")
  results = {"environment": env,
             "command": "python -m experiments.benchmarks " + " ".join(
                 sys.argv[1:]),
             "sizes": dataclasses.asdict(sizes),
             "sizing": dataclasses.asdict(sizing),
             "measured": measure(sizes, log)}
  timing.end_environment(env)
  timing.write_results(out_dir, "batch_benchmark", quick, results,
                       to_markdown(results))
  return results
