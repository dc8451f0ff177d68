"""The GPU command's mpm part: the MPM's speed here, and its agreement.

The paper scene (1000 particles, one semicircle, 600 frames) one at a time
(``mpm.simulate``'s clock) and B copies of it vmapped
(``jax.vmap(mpm.solver.rollout)``, chunks of 50 frames copied to the host as
``mpm.simulate_setups`` does), seconds per trajectory and particle-substeps
per second; the batch ``mpm.batch_sizing.batch_size_for`` picks from the
device's memory statistics, run for one chunk; a batch of the paper
dataset's own scenes (``mpm.dataset.plan``, 700-1500 particles) timed and
extrapolated to its 1,100 trajectories; the study of
``experiments.tradeoff`` (the paper scene at several particle spacings) per
trajectory; and the paper scene's agreement with a CPU
(``mpm_agreement``; the tolerances and why: ``gpu_benchmark``).
"""

import dataclasses
import math
from typing import Any, Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from experiments import timing
from experiments.benchmarks import gpu_agreement
from experiments.benchmarks import scenes
from experiments.benchmarks.gpu_report import PAPER_DATASET
from experiments.benchmarks.gpu_sizes import Sizes
from experiments.studies import tradeoff as tradeoff_study
import mpm
from mpm import dataset as mpm_dataset
from mpm import batch_sizing
from mpm import simulation


def paper_scene(num_frames: int) -> mpm.Scene:
  """The paper scene (``scenes.PAPER_SCENE``) for ``num_frames`` frames; the
  gns part's trajectories start from it too."""
  return mpm.Scene.from_dict({**scenes.PAPER_SCENE, "num_frames": num_frames})


def _is_out_of_memory(e: Exception) -> bool:
  return "RESOURCE_EXHAUSTED" in str(e) or "out of memory" in str(e).lower()


_vmapped = jax.jit(jax.vmap(mpm.solver.rollout,
                            in_axes=(0, 0, 0, None, None, None)),
                   static_argnums=(3, 4, 5))


# Compiled vmapped programs by (copies, frames per call, setup's shapes).
_programs: dict = {}


def _copies(setup: mpm.Setup, b: int):
  """(state, params, field) of ``b`` copies of ``setup``, batch axis first."""
  stack = lambda a: jnp.broadcast_to(a, (b,) + a.shape).copy()
  return tuple(jax.tree.map(stack, getattr(setup, k))
               for k in ("state", "params", "field"))


def time_vmapped(setup: mpm.Setup, b: int, frames: int, chunk: int,
                 repeats: int) -> dict[str, Any]:
  """``b`` copies of ``setup`` as one vmapped program for ``frames``.

  Compiled once (``compile_s``); each call runs the chunks of ``chunk``
  frames from the initial state, copying each chunk's positions to the
  host as ``mpm.simulate_setups`` does; ``repeats`` calls after a warm-up.

  Returns:
    ``timing.time_calls``' summary (seconds per call) with ``compile_s``,
    ``substeps_run`` (per scene) and ``finite`` (every frame finite).
  """
  n_chunks, per = simulation.chunking(frames, chunk)
  args = _copies(setup, b)
  key = (b, per, setup.spec, setup.n_substeps, setup.state.x.shape,
         setup.field.index.shape)
  if key not in _programs:
    _programs[key] = timing.compile_program(_vmapped, *args, setup.spec, per,
                                            setup.n_substeps)
  program = _programs[key]
  finite = []

  def run():
    state, params, field = args
    for _ in range(n_chunks):
      state, x, _, ok = program(state, params, field)
      np.asarray(x)  # to the host, as the library does
    finite.append(bool(np.all(np.asarray(ok))))
    return state

  seconds = timing.time_calls({"batch": run}, repeats)["batch"]
  return {**seconds, "compile_s": program.compile_s,
          "substeps_run": n_chunks * per * setup.n_substeps,
          "finite": all(finite)}


def _rate_row(seconds: float, scenes_run: int, particles: int,
              substeps_run: int, trajectory_substeps: int) -> dict[str, Any]:
  """Seconds per trajectory (per scene, scaled to a whole trajectory's
  substeps) and particle-substeps per second of a timed call."""
  return {"s_per_trajectory": seconds / scenes_run * trajectory_substeps
                              / substeps_run,
          "particle_substeps_per_s": scenes_run * particles * substeps_run
                                     / seconds,
          "extrapolated": substeps_run < trajectory_substeps}


def mpm_positions(scene: mpm.Scene, frames: Sequence[int],
                  perturb: bool = False) -> np.ndarray:
  """The scene's sand at ``frames`` [len(frames), N, 2] on this device
  (from positions one float32 ulp to the right if ``perturb``)."""
  s = mpm.setup(scene)
  if perturb:
    x0 = np.asarray(s.state.x)[:s.n_particles]
    s = mpm.setup(scene, gpu_agreement.one_ulp(x0))
  return mpm.simulate_setups([s])[0].positions[list(frames)]


def measure_mpm(sizes: Sizes, log: Callable[[str], None],
                save: Callable[[dict], None],
                agree: Callable[[dict], None]) -> dict[str, Any]:
  """The mpm part: one at a time and its agreement (``agree`` adds the
  comparisons to ``out["agreement"]``), vmapped, the largest batch, the
  dataset, the spacings; ``save`` is called with what is measured so far
  after each of them, the most telling first."""
  scene = paper_scene(sizes.frames)
  setup = mpm.setup(scene)
  n, nsub = setup.n_particles, setup.n_substeps
  trajectory_substeps = (sizes.frames - 1) * nsub
  out: dict[str, Any] = {"scene": {
      "name": scene.name, "n_particles": n,
      "n_particles_padded": int(setup.state.x.shape[0]),
      "frames": sizes.frames, "n_substeps_per_frame": nsub,
      "grid_shape": list(setup.spec.shape),
      "n_boundary_nodes": int(setup.field.index.shape[0])}}

  first, walls = timing.self_timed(lambda: mpm.simulate(scene), sizes.repeats,
                                   lambda r: r.wall_time_s)
  n_chunks, per = simulation.chunking(sizes.frames, 50)
  run = n_chunks * per * nsub
  out["single"] = {**walls, "compile_s": first.compile_time_s,
                   "substeps_run": run,
                   **_rate_row(walls["median_s"], 1, n, run, run)}
  out["single"]["extrapolated"] = False
  log(f"paper scene, one at a time (mpm.simulate): "
      f"{walls['median_s']:.3f} s per {sizes.frames}-frame trajectory "
      f"({out['single']['particle_substeps_per_s']:.3g} particle-substeps/s;"
      f" compile {first.compile_time_s:.1f} s excluded)")
  frames = gpu_agreement.agreement_frames(sizes)
  out["agreement"] = {"frames": frames,
                      "positions": gpu_agreement.encode_positions(
                          first.positions[frames])}
  agree(out)
  save(out)

  out["vmapped"] = []
  for b in sizes.batch_sizes:
    t = time_vmapped(setup, b, min(sizes.batch_frames, sizes.frames),
                     sizes.chunk_frames, sizes.batch_repeats)
    row = {"batch": b, **t, **_rate_row(t["median_s"], b, n,
                                        t["substeps_run"],
                                        trajectory_substeps)}
    out["vmapped"].append(row)
    log(f"vmapped x{b}: {row['median_s']:.3f} s per call, "
        f"{row['s_per_trajectory']:.4f} s per trajectory"
        + (" (extrapolated)" if row["extrapolated"] else "")
        + f", {row['particle_substeps_per_s']:.3g} particle-substeps/s")
    save(out)

  out["largest_batch"] = measure_largest_batch(scene, setup, sizes, log)
  save(out)
  out["dataset"] = measure_dataset(sizes, log)
  save(out)
  out["spacings"] = []
  for spacing in sizes.spacings:
    out["spacings"].append(measure_spacing(sizes, spacing, log))
    save(out)
  return out


def measure_largest_batch(scene: mpm.Scene, setup: mpm.Setup, sizes: Sizes,
                          log: Callable[[str], None]) -> dict[str, Any]:
  """The batch ``batch_size_for`` picks (from ``memory_stats()``; its
  fallback on the CPU), capped at ``sizes.max_batch``, run for one chunk;
  halved on running out of memory."""
  chunk = min(sizes.chunk_frames, sizes.frames - 1) + 1
  sizing = batch_sizing.batch_size_for(scene, chunk_frames=chunk - 1)
  out = {"sizing": dataclasses.asdict(sizing), "cap": sizes.max_batch,
         "frames": chunk, "failed": []}
  b = min(sizing.batch, sizes.max_batch)
  while b >= 1:
    try:
      t = time_vmapped(setup, b, chunk, chunk, 1)
    except Exception as e:  # pylint: disable=broad-except
      if not _is_out_of_memory(e):
        raise
      out["failed"].append({"batch": b, "error": str(e).splitlines()[0]})
      log(f"largest batch: {b} scenes ran out of memory; halving")
      b //= 2
      continue
    out.update(batch=b, **t, **_rate_row(
        t["median_s"], b, setup.n_particles, t["substeps_run"],
        (sizes.frames - 1) * setup.n_substeps))
    log(f"largest batch ({sizing.source}): {b} scenes, "
        f"{out['particle_substeps_per_s']:.3g} particle-substeps/s over "
        f"{chunk - 1} frames; per scene "
        f"{sizing.per_scene_bytes / 2**20:.2f} MiB")
    return out
  return out


def measure_dataset(sizes: Sizes, log: Callable[[str], None]
                    ) -> dict[str, Any]:
  """A batch of the paper dataset's first training scenes through
  ``mpm.simulate_batch``, extrapolated to its 1,100 trajectories."""
  spec = mpm_dataset.DatasetSpec(num_train=sizes.dataset_batch, num_test=1,
                                 num_frames=sizes.dataset_frames)
  planned = [p.scene for p in mpm_dataset.plan(spec)
             if p.split == "train"][:sizes.dataset_batch]
  first, walls = timing.self_timed(
      lambda: mpm.simulate_batch(planned, chunk_frames=sizes.chunk_frames),
      1, lambda r: r[0].wall_time_s * len(r))
  n_chunks, per = simulation.chunking(sizes.dataset_frames,
                                      sizes.chunk_frames)
  steps_run = n_chunks * per
  batch_s = walls["median_s"] * (600 - 1) / steps_run
  total_h = batch_s * math.ceil(PAPER_DATASET / len(planned)) / 3600
  out = {"batch": len(planned), "frames_run": sizes.dataset_frames,
         "particles": [s.granular.num_particles for s in planned],
         "n_substeps_per_frame": first[0].n_substeps,
         "batch_s": walls["median_s"], "compile_s": first[0].compile_time_s,
         "batch_s_600_frames": batch_s, "dataset_h": total_h,
         "extrapolated_frames": steps_run < 599}
  log(f"dataset: {len(planned)} of its scenes in one batch, "
      f"{walls['median_s']:.2f} s for {sizes.dataset_frames} frames -> "
      f"{PAPER_DATASET} trajectories of 600 frames in {total_h:.3g} h "
      "(simulation only, extrapolated)")
  return out


def measure_spacing(sizes: Sizes, spacing: float,
                    log: Callable[[str], None]) -> dict[str, Any]:
  """Seconds per trajectory of the paper scene at one spacing (m) of the
  speed/accuracy study (``experiments.studies.tradeoff.at_spacing``)."""
  scene = tradeoff_study.at_spacing(paper_scene(sizes.frames), spacing)
  first, walls = timing.self_timed(lambda: mpm.simulate(scene),
                                   max(1, sizes.repeats - 1),
                                   lambda r: r.wall_time_s)
  log(f"spacing {spacing * 1000:g} mm ({scene.granular.num_particles} "
      f"particles): {walls['median_s']:.3f} s per trajectory")
  return {"spacing_m": spacing, "particles": scene.granular.num_particles,
          "n_substeps_per_frame": first.n_substeps,
          "s_per_trajectory": walls["median_s"], **walls,
          "compile_s": first.compile_time_s}


def mpm_agreement(out: dict, sizes: Sizes, twin, reference: dict | None,
                  envelope_here: bool) -> None:
  """Adds the MPM's comparisons to ``out["agreement"]``: against the twin
  (with its envelope), against the reference, and (on the CPU, where this
  process is the reference) the envelope of this device."""
  compare, decode = gpu_agreement.compare, gpu_agreement.decode_positions
  a = out["agreement"]
  mine = decode(a["positions"])
  scene = paper_scene(sizes.frames)
  if envelope_here:
    a["envelope"] = compare(mine, mpm_positions(scene, a["frames"],
                                                perturb=True), "mpm")
  if twin is not None:
    cpu = twin("mpm")
    a["twin"] = {"envelope": compare(decode(cpu["positions"]),
                                     decode(cpu["perturbed"]), "mpm"),
                 "default": compare(mine, decode(cpu["positions"]), "mpm")}
  ref = gpu_agreement.reference_part(reference, "mpm")
  if ref is not None and ref["agreement"]["frames"] == a["frames"]:
    a["reference"] = compare(
        mine, decode(ref["agreement"]["positions"]), "mpm")

