"""MPM benchmark: cost per substep and per trajectory, scaling, batching, peer.

  python -m experiments.benchmarks --what=mpm --out=docs/benchmarks

One library call, :func:`run_benchmark`, measures the JAX MLS-MPM solver and
writes what it measured (``mpm_benchmark.json`` and ``.md``) to a directory:

1. the paper scene (1000 particles, one semicircle): microseconds per substep
   (``jax.jit`` of ``mpm.solver.rollout`` over a few frames) and seconds per
   600-frame trajectory (``mpm.simulate``'s ``wall_time_s``);
2. cost against particle count and obstacle count (us/substep);
3. throughput of vmapped batches (``mpm.simulate_setups`` on several scenes)
   against the single-scene path on the same scenes;
4. a peer, MLS-MPM of the same scene and physics in Taichi (CPU backend,
   ``taichi_peer.py``), timed the same way in the same run, and
   checked to be the same physics: positions after a few frames agree with
   the JAX solver's.

Timing follows ``timing``'s rules: compilation and a warm-up run excluded;
every JAX call waited on with ``jax.block_until_ready``, every Taichi run
with ``ti.sync()``; each figure the median of repeats (the minimum recorded
beside it); peers in the same process on the same scenes; ratios beside
absolute times.

Taichi is optional (``pip install -e .[bench]``): without it the peer is
skipped with a message and the rest runs.
"""

import dataclasses
import importlib
import statistics
from typing import Any, Callable

from absl import logging
import jax
import jax.numpy as jnp
import numpy as np

import mpm
from experiments import timing
from experiments.benchmarks import scenes

# A granular box large enough for 5000 particles at 0.005 m spacing (the
# default box holds ~3300 above the ramp); used for every row of the particle
# sweep so that only the particle count changes.
LARGE_BOX = (1.1, 0.3, 1.46, 1.19)
# Positions of the peer within this distance [m] of the JAX solver's count as
# the same physics (a tenth of a percent of a cell at dx = 0.01 m).
AGREEMENT_TOLERANCE_M = 1e-5

_rollout = jax.jit(mpm.solver.rollout,
                   static_argnames=("spec", "n_frames", "n_substeps", "remat"))


@dataclasses.dataclass(frozen=True)
class Sizes:
  """What to measure, and how much.

  Attributes:
    substep_frames: frames per timed rollout when timing one substep.
    repeats: timed repeats of each measurement (median reported).
    trajectory_frames: frames of the timed trajectory (600 in the paper).
    trajectory_repeats: timed repeats of the whole trajectory.
    particle_counts: particle sweep (one obstacle, ``LARGE_BOX``).
    obstacle_counts: obstacle sweep (``sweep_particles`` particles).
    sweep_particles: particles of the obstacle sweep and of batch scenes.
    batch_sizes: scenes per vmapped batch.
    batch_frames: frames per timed batch run.
    single_reference_scenes: scenes of the batch also run one at a time.
    agreement_frames: frames after which the peer's positions are compared.
    agreement_svds: the peer's SVDs to compare ("closed_form", the one timed,
      and "taichi", ``ti.svd``; see ``taichi_peer.SVD_KINDS``).
    seed: first seed of the sampled scenes.
  """
  substep_frames: int = 10
  repeats: int = 7
  trajectory_frames: int = 600
  trajectory_repeats: int = 3
  particle_counts: tuple[int, ...] = (700, 1000, 1500, 5000)
  obstacle_counts: tuple[int, ...] = (0, 1, 2)
  sweep_particles: int = 1000
  batch_sizes: tuple[int, ...] = (8, 32)
  batch_frames: int = 4
  single_reference_scenes: int = 4
  agreement_frames: int = 20
  agreement_svds: tuple[str, ...] = ("closed_form", "taichi")
  seed: int = 0


FULL = Sizes()
# Tiny sizes that exercise every measurement in seconds (smoke tests).
QUICK = Sizes(substep_frames=1, repeats=2, trajectory_frames=11,
              trajectory_repeats=1, particle_counts=(100,),
              obstacle_counts=(0,), sweep_particles=100, batch_sizes=(2,),
              batch_frames=1, single_reference_scenes=1, agreement_frames=3,
              agreement_svds=("closed_form",))


# ---------------------------------------------------------------- timing ---


def time_jax_substeps(setup: mpm.Setup, n_frames: int,
                      repeats: int) -> dict[str, Any]:
  """Microseconds per substep of ``jax.jit(mpm.solver.rollout)``.

  Compiles once (``compile_s``, excluded), then times ``repeats`` rollouts of
  ``n_frames`` frames from the initial state after a warm-up.
  """
  args = (setup.state, setup.params, setup.field)
  program = timing.compile_program(_rollout, *args, spec=setup.spec,
                                   n_frames=n_frames,
                                   n_substeps=setup.n_substeps)
  seconds = timing.time_calls({"jax": lambda: program(*args)}, repeats)
  return {**timing.per_unit_us(seconds["jax"], n_frames * setup.n_substeps),
          "compile_s": program.compile_s}


def time_peer_substeps(peer, n_frames: int, repeats: int) -> dict[str, Any]:
  """Microseconds per substep of the Taichi peer, measured as the JAX one:
  a warm-up (``warmup_s``: kernel compilation included) first, each repeat
  from the initial state (reset outside the clock); ``run_substeps`` ends
  with ``ti.sync()``."""
  n = n_frames * peer.n_substeps
  seconds = timing.time_calls({"taichi": lambda: peer.run_substeps(n)},
                              repeats, prepare={"taichi": peer.reset})
  return {**timing.per_unit_us(seconds["taichi"], n),
          "warmup_s": seconds["taichi"]["warmup_s"]}


def _ratio(a: float | None, b: float | None) -> float | None:
  return None if a is None or b is None else a / b


# ------------------------------------------------------------------ peer ---


class _Peer:
  """Lazily imported Taichi peer; ``available`` is False without taichi."""

  def __init__(self, enabled: bool, num_threads: int | None):
    self.available = False
    self.reason = "disabled (--notaichi)"
    self.info: dict[str, Any] = {}
    self._built: dict = {}
    if not enabled:
      return
    try:
      taichi_peer = importlib.import_module(
          "experiments.benchmarks.taichi_peer")
    except ImportError as e:
      self.reason = (f"taichi is not importable ({e}); install the optional "
                     "dependency with `pip install -e .[bench]`")
      return
    self.module = taichi_peer
    self.info = taichi_peer.init(num_threads)
    self.available = True
    self.reason = ""

  def build(self, setup: mpm.Setup, svd: str = "closed_form"):
    """The peer of ``setup`` (built once: Taichi compiles per instance)."""
    key = (id(setup), svd)
    if key not in self._built:
      self._built[key] = (setup, self.module.TaichiMPM(setup, svd=svd))
    return self._built[key][1]


# ------------------------------------------------------------ measurements ---


def _scene_info(setup: mpm.Setup) -> dict[str, Any]:
  return {"name": setup.scene.name,
          "n_particles": setup.n_particles,
          "n_particles_padded": int(setup.state.x.shape[0]),
          "n_obstacles": len(setup.scene.obstacles),
          "obstacles": [o.to_dict() for o in setup.scene.obstacles],
          "granular_box": list(setup.scene.granular.box),
          "n_substeps_per_frame": setup.n_substeps,
          "dt_s": float(np.asarray(setup.params.dt)),
          "grid_shape": list(setup.spec.shape),
          "n_boundary_nodes": int(setup.field.index.shape[0])}


def _substep_row(setup: mpm.Setup, sizes: Sizes, peer: _Peer,
                 log: Callable[[str], None], label: str) -> dict[str, Any]:
  """JAX and (if available) Taichi us/substep of one scene."""
  row = _scene_info(setup)
  row["jax"] = time_jax_substeps(setup, sizes.substep_frames, sizes.repeats)
  jax_us = row["jax"]["median_us"]
  msg = (f"{label}: JAX {jax_us:.1f} us/substep (median of {sizes.repeats} "
         f"x {row['jax']['units_per_repeat']} substeps; min "
         f"{row['jax']['min_us']:.1f}; compile "
         f"{row['jax']['compile_s']:.1f} s)")
  if peer.available:
    row["taichi"] = time_peer_substeps(peer.build(setup), sizes.substep_frames,
                                       sizes.repeats)
    row["taichi_over_jax"] = _ratio(row["taichi"]["median_us"], jax_us)
    msg += (f"; Taichi {row['taichi']['median_us']:.1f} us/substep "
            f"(Taichi/JAX {row['taichi_over_jax']:.2f})")
  log(msg)
  return row


def measure_paper_scene(setup: mpm.Setup, sizes: Sizes, peer: _Peer,
                        log: Callable[[str], None]) -> dict[str, Any]:
  """Item 1 (and the peer's timing): the paper scene per substep and per
  trajectory of ``setup.scene.num_frames`` frames."""
  scene = setup.scene
  out = _substep_row(setup, sizes, peer, log, "paper scene")

  # Whole trajectories through the user-facing path: mpm.simulate's
  # wall_time_s excludes compilation; a first run warms up.
  first, walls = timing.self_timed(lambda: mpm.simulate(scene),
                                   sizes.trajectory_repeats,
                                   lambda result: result.wall_time_s)
  n_chunks, chunk = mpm.simulation.chunking(scene.num_frames, 50)
  substeps = n_chunks * chunk * setup.n_substeps
  out["trajectory"] = {
      "frames": scene.num_frames, "substeps_run": substeps,
      "jax_s": walls["median_s"], "jax_min_s": walls["min_s"],
      "repeats": walls["repeats"], "compile_s": first.compile_time_s,
      "jax_us_per_substep": walls["median_s"] / substeps * 1e6}
  log(f"paper scene, {scene.num_frames}-frame trajectory (mpm.simulate, "
      f"{substeps} substeps): JAX {out['trajectory']['jax_s']:.2f} s (median "
      f"of {walls['repeats']}; compile {first.compile_time_s:.1f} s "
      "excluded)")
  if peer.available:
    p = peer.build(setup)
    # Positions are copied out every frame, as mpm.simulate does.
    seconds = timing.time_calls(
        {"taichi": lambda: p.advance(scene.num_frames - 1)},
        sizes.trajectory_repeats, prepare={"taichi": p.reset})["taichi"]
    t = out["trajectory"]
    t["taichi_s"] = seconds["median_s"]
    t["taichi_substeps_run"] = (scene.num_frames - 1) * setup.n_substeps
    t["taichi_over_jax"] = _ratio(
        t["taichi_s"] / t["taichi_substeps_run"], t["jax_s"] / substeps)
    log(f"paper scene, {scene.num_frames}-frame trajectory: Taichi "
        f"{t['taichi_s']:.2f} s ({t['taichi_substeps_run']} substeps, median "
        f"of {seconds['repeats']})")
  return out


def measure_agreement(setup: mpm.Setup, sizes: Sizes, peer: _Peer,
                      log: Callable[[str], None]) -> dict[str, Any]:
  """Item 4's check: the peer's positions after each of the first frames
  against the JAX solver's, for each SVD in ``sizes.agreement_svds``."""
  if not peer.available:
    return {"skipped": peer.reason}
  k = sizes.agreement_frames
  _, jax_x, _, _ = _rollout(setup.state, setup.params, setup.field,
                            spec=setup.spec, n_frames=k,
                            n_substeps=setup.n_substeps)
  n = setup.n_particles  # real particles; padding beyond
  jax_x = np.asarray(jax_x)[:, :n]
  x0 = np.asarray(setup.state.x)[:n]
  displacement = float(np.max(np.linalg.norm(jax_x[-1] - x0, axis=-1)))
  out = {"frames": k, "tolerance_m": AGREEMENT_TOLERANCE_M,
         "max_displacement_m": displacement, "svd": {}}
  for svd in sizes.agreement_svds:
    p = peer.build(setup, svd=svd)
    p.reset()
    ti_x = p.advance(k)[:, :n]
    diff = np.linalg.norm(ti_x - jax_x, axis=-1)  # [k, N]
    per_frame = [float(d) for d in diff.max(-1)]
    r = out["svd"][svd] = {
        "max_diff_m": per_frame[-1],
        "rms_diff_m": float(np.sqrt(np.mean(diff[-1]**2))),
        "max_diff_per_frame_m": per_frame,
        "agrees": bool(per_frame[-1] <= AGREEMENT_TOLERANCE_M)}
    log(f"peer agreement ({svd} SVD), after {k} frames: max |x_taichi - "
        f"x_jax| = {per_frame[-1]:.3g} m (rms {r['rms_diff_m']:.3g} m; sand "
        f"moved up to {displacement:.3g} m; tolerance "
        f"{AGREEMENT_TOLERANCE_M:g} m: "
        f"{'agrees' if r['agrees'] else 'DIFFERS'})")
  return out


def measure_particle_scaling(sizes: Sizes, peer: _Peer,
                             log: Callable[[str], None]) -> list[dict]:
  """Item 2a: us/substep against particle count (one obstacle)."""
  rows = []
  for n in sizes.particle_counts:
    scene = mpm.sample_scene(
        sizes.seed, num_particles=n, num_obstacles=1,
        granular={"box": list(LARGE_BOX), "spacing": 0.005,
                  "num_particles": n})
    row = _substep_row(mpm.setup(scene), sizes, peer, log,
                       f"{n} particles, 1 obstacle")
    row["jax_ns_per_particle_substep"] = row["jax"]["median_us"] / n * 1e3
    rows.append(row)
  return rows


def measure_obstacle_scaling(sizes: Sizes, peer: _Peer,
                             log: Callable[[str], None]) -> list[dict]:
  """Item 2b: us/substep against obstacle count."""
  rows = []
  for k in sizes.obstacle_counts:
    scene = mpm.sample_scene(sizes.seed, num_particles=sizes.sweep_particles,
                             num_obstacles=k)
    rows.append(_substep_row(mpm.setup(scene), sizes, peer, log,
                             f"{sizes.sweep_particles} particles, {k} "
                             "obstacle(s)"))
  return rows


def _time_setups(setups: list[mpm.Setup], frames: int,
                 repeats: int) -> list[float]:
  """Seconds of ``repeats`` warm runs of ``mpm.simulate_setups`` (one chunk
  of ``frames`` frames; its wall_time_s excludes compilation and is shared
  out among the scenes, hence the product)."""
  _, seconds = timing.self_timed(
      lambda: mpm.simulate_setups(setups, chunk_frames=frames), repeats,
      lambda results: results[0].wall_time_s * len(results))
  return seconds["all_s"]


def measure_batches(sizes: Sizes, log: Callable[[str], None]) -> dict:
  """Item 3: vmapped batches against the same scenes run one at a time."""
  frames = sizes.batch_frames
  n_max = max(sizes.batch_sizes)
  scenes = [mpm.sample_scene(sizes.seed + 1000 + i,
                             num_particles=sizes.sweep_particles,
                             num_frames=frames + 1)
            for i in range(n_max)]
  setups = [mpm.setup(s) for s in scenes]
  # As mpm.simulate_batch: one substep count, the largest any scene needs.
  n_substeps = max(s.n_substeps for s in setups)
  setups = [dataclasses.replace(
      s, n_substeps=n_substeps, params=s.params.replace(
          dt=jnp.asarray(s.scene.frame_dt / n_substeps, jnp.float32)))
            for s in setups]
  trajectory_substeps = (FULL.trajectory_frames - 1) * n_substeps

  single = []
  for s in setups[:sizes.single_reference_scenes]:
    seconds = _time_setups([s], frames, sizes.repeats)
    single.append(statistics.median(seconds) / (frames * n_substeps) * 1e6)
  single_us = statistics.median(single)
  out = {"frames": frames, "n_substeps_per_frame": n_substeps,
         "particles_per_scene": sizes.sweep_particles,
         "single": {"scenes": len(single), "us_per_substep": single_us,
                    "us_per_substep_each": single,
                    "scenes_per_s": 1e6 / (single_us * trajectory_substeps)},
         "batches": []}
  log(f"single-scene path ({len(single)} scenes of the batch, one at a "
      f"time): {single_us:.1f} us/substep")
  for b in sizes.batch_sizes:
    seconds = _time_setups(setups[:b], frames, sizes.repeats)
    per = [t / (b * frames * n_substeps) * 1e6 for t in seconds]
    us = statistics.median(per)
    row = {"batch": b, "us_per_scene_substep": us, "min_us": min(per),
           "repeats": len(per),
           "us_per_batch_substep": us * b,
           "scenes_per_s": 1e6 / (us * trajectory_substeps),
           "speedup_vs_single": single_us / us}
    out["batches"].append(row)
    log(f"batch of {b} (vmap): {us:.1f} us per scene-substep, "
        f"{row['scenes_per_s']:.3f} scenes/s projected to "
        f"{FULL.trajectory_frames}-frame trajectories "
        f"({row['speedup_vs_single']:.2f}x the single-scene path)")
  out["note"] = (f"scenes/s projected to {FULL.trajectory_frames}-frame "
                 f"trajectories ({trajectory_substeps} substeps) from "
                 f"{frames}-frame runs")
  return out


# ---------------------------------------------------------------- output ---


def _fmt(v, spec=".1f", none="n/a"):
  return none if v is None else format(v, spec)


def to_markdown(results: dict[str, Any]) -> str:
  """The results as Markdown tables."""
  env = results["environment"]
  lines = [
      "# MPM benchmark", "",
      f"{env['date']}, {env['platform']}, {env['cpu_count']} CPU cores, "
      f"jax {env['jax_version']} ({env['jax_backend']}), Taichi "
      f"{env['taichi'].get('taichi_version', 'skipped')} (CPU, threads: "
      f"{env['taichi'].get('num_threads', '-')}). Load average at start "
      f"{env['load_average_start'][0]:.2f}, at end "
      f"{env['load_average_end'][0]:.2f}."
      + (" **Quick mode (tiny sizes): not representative.**"
         if env["quick"] else ""), "",
      "Medians of repeats; compilation and a warm-up run excluded; "
      "`jax.block_until_ready` / `ti.sync()` before the clock stops. "
      "us/substep: `jax.jit(mpm.solver.rollout)` over a few frames; "
      "trajectory: `mpm.simulate` (`wall_time_s`).", ""]
  if not env["taichi"].get("taichi_version"):
    lines += [f"Taichi peer skipped: {env['taichi']['skipped']}", ""]

  p = results["paper_scene"]
  t = p["trajectory"]
  lines += [
      f"## Paper scene ({p['n_particles']} particles (padded to "
      f"{p['n_particles_padded']}), one semicircle, "
      f"{p['n_substeps_per_frame']} substeps/frame, grid "
      f"{p['grid_shape'][0]}x{p['grid_shape'][1]})", "",
      "| solver | us/substep | s per trajectory | ratio to JAX |",
      "| --- | ---: | ---: | ---: |",
      f"| JAX (jit, CPU) | {p['jax']['median_us']:.1f} | {t['jax_s']:.2f} "
      f"({t['frames']} frames) | 1 |"]
  if "taichi" in p:
    lines.append(
        f"| Taichi (CPU) | {p['taichi']['median_us']:.1f} | "
        f"{_fmt(t.get('taichi_s'), '.2f')} | "
        f"{_fmt(p.get('taichi_over_jax'), '.2f')} (substep), "
        f"{_fmt(t.get('taichi_over_jax'), '.2f')} (trajectory) |")
  lines.append("")

  a = results["agreement"]
  if "svd" in a:
    lines += [f"## Peer agreement (paper scene, after {a['frames']} frames; "
              f"sand moved up to {a['max_displacement_m']:.3g} m)", "",
              "| Taichi SVD | max abs diff (m) | rms diff (m) | within "
              f"{a['tolerance_m']:g} m |", "| --- | ---: | ---: | --- |"]
    for svd, r in a["svd"].items():
      lines.append(f"| {svd} | {r['max_diff_m']:.3g} | {r['rms_diff_m']:.3g}"
                   f" | {'yes' if r['agrees'] else 'no'} |")
    lines += ["", "The timed peer uses the closed-form 2x2 SVD; `ti.svd` "
              "(\"taichi\") zeroes the stretch's off-diagonal below 1e-5, so "
              "small shear strains never build up near F = I (a systematic "
              "difference, not float32 chaos).", ""]

  for title, key, first in (
      ("Particle count (one obstacle, box "
       f"{list(LARGE_BOX)})", "particle_scaling", "particles"),
      ("Obstacle count", "obstacle_scaling", "obstacles")):
    lines += [f"## {title}", "",
              f"| {first} | padded particles, nodes | substeps/frame | "
              "JAX us/substep "
              "| Taichi us/substep | Taichi/JAX |",
              "| ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in results[key]:
      v = r["n_particles"] if first == "particles" else r["n_obstacles"]
      lines.append(
          f"| {v} | {r['n_particles_padded']}, {r['n_boundary_nodes']} | "
          f"{r['n_substeps_per_frame']} | "
          f"{r['jax']['median_us']:.1f} | "
          f"{_fmt(r.get('taichi', {}).get('median_us'))} | "
          f"{_fmt(r.get('taichi_over_jax'), '.2f')} |")
    lines.append("")

  b = results["batches"]
  lines += [f"## Batches (vmap, {b['particles_per_scene']}-particle sampled "
            f"scenes, {b['n_substeps_per_frame']} substeps/frame)", "",
            "| scenes | us per scene-substep | us per batch-substep | "
            "scenes/s | vs single |", "| ---: | ---: | ---: | ---: | ---: |",
            f"| 1 (single path) | {b['single']['us_per_substep']:.1f} | "
            f"{b['single']['us_per_substep']:.1f} | "
            f"{b['single']['scenes_per_s']:.3f} | 1 |"]
  for r in b["batches"]:
    lines.append(f"| {r['batch']} | {r['us_per_scene_substep']:.1f} | "
                 f"{r['us_per_batch_substep']:.1f} | {r['scenes_per_s']:.3f}"
                 f" | {r['speedup_vs_single']:.2f}x |")
  lines += ["", f"({b['note']}.)", ""]
  return "\n".join(lines)


def run_benchmark(out_dir: str, *, quick: bool = False, taichi: bool = True,
                  taichi_threads: int | None = None,
                  log: Callable[[str], None] = logging.info
                  ) -> dict[str, Any]:
  """Runs every measurement and writes ``mpm_benchmark[_quick].{json,md}``.

  Args:
    out_dir: directory for the results (created if missing).
    quick: tiny sizes (``QUICK``), seconds instead of minutes.
    taichi: run the Taichi peer if taichi is importable.
    taichi_threads: CPU threads for Taichi (default: all cores).
    log: called with one line per measurement.

  Returns:
    The results (the JSON's content) with the Markdown under "markdown".
  """
  sizes = QUICK if quick else FULL
  peer = _Peer(taichi, taichi_threads)
  if not peer.available:
    log(f"Taichi peer skipped: {peer.reason}")
  results: dict[str, Any] = {"environment": timing.environment(
      quick, taichi=peer.info if peer.available else {"skipped": peer.reason}),
                             "sizes": dataclasses.asdict(sizes)}
  paper = mpm.setup(mpm.Scene.from_dict(
      {**scenes.PAPER_SCENE, "num_frames": sizes.trajectory_frames}))
  results["paper_scene"] = measure_paper_scene(paper, sizes, peer, log)
  results["agreement"] = measure_agreement(paper, sizes, peer, log)
  results["particle_scaling"] = measure_particle_scaling(sizes, peer, log)
  results["obstacle_scaling"] = measure_obstacle_scaling(sizes, peer, log)
  results["batches"] = measure_batches(sizes, log)
  timing.end_environment(results["environment"])
  timing.write_results(out_dir, "mpm_benchmark", quick, results,
                       to_markdown(results))
  return results
