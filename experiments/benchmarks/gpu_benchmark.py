"""Every accelerator figure in one command: MPM, GNS, training, agreement.

  python -m experiments.benchmarks --what=gpu --out=DIR \\
      [--gpu_parts=mpm,gns,train] [--cpu_reference=FILE]
  bash experiments/benchmarks/gpu.sh     # on an accelerator machine
                                         # (docs/performance.md)

One library call per part, :func:`run_part`, measures on this process's
first device and writes ``<stem>_<part>.json``; :func:`write_report`
assembles the parts found in the directory with the CPU reference into
``<stem>_benchmark.{json,md}`` (``run_benchmark`` does both). On an
accelerator the stem is ``gpu``; on the CPU it is ``gpu_cpu`` and the report
``gpu_cpu_reference.{json,md}``: the same programs at sizes one CPU core runs
in minutes, committed so that every accelerator figure has this project's
CPU figure beside it (``--cpu_reference``; the accelerator machine's own CPU
is another CPU). The parts:

mpm: the paper scene (1000 particles, one semicircle, 600 frames) one at a
  time (``mpm.simulate``'s clock) and B copies of it vmapped
  (``jax.vmap(mpm.solver.rollout)``, chunks of 50 frames copied to the host
  as ``mpm.simulate_setups`` does), seconds per trajectory and
  particle-substeps per second; the batch ``mpm.batch_sizing.batch_size_for``
  picks from the device's memory statistics, run for one chunk; a batch of
  the paper dataset's own scenes (``mpm.dataset.plan``, 700-1500
  particles) timed and extrapolated to its 1,100 trajectories; the study of
  ``experiments.tradeoff`` (the paper scene at several particle spacings)
  per trajectory; and the agreement below.
gns: the paper model (``configs/paper.py``: latent 128, 10 message-passing
  steps, boundary particles as nodes) rolling out the paper trajectory
  (594 learned steps after C = 6 input frames) alone and as B copies in one
  vmapped rollout: seconds per simulation, the paper's Table 2 measure. The
  model has its initial parameters with the decoder's last layer set to
  zero, so it predicts the data's mean acceleration and the sand stays
  close to its start: the graph keeps the dense heap's edges (about the
  most a trajectory has) and every step does a trained model's work, whose
  cost does not depend on the parameters' values. Also the shipped small
  model (``experiments/pretrained/small``) on its own scene, the learned row
  of the speed/accuracy study.
train: steps per second of ``train.train_and_evaluate`` with the paper
  config (batch 2, host batches, graphs built per step) on a dataset of
  paper trajectories generated first, evaluation off; the median of
  ``log_every`` intervals after a warm-up, projected to 1.5 M and 2 M steps
  beside the paper's 81.5 h and 134 h on a V100.

Agreement: the paper scene after ``AGREEMENT_EARLY_FRAME`` frames and after
599, and the small model's rollout after a few steps and at its end, on this
device against the same runs on a CPU: the accelerator machine's own CPU
(a child process with ``JAX_PLATFORMS=cpu``, same jax) and this project's
CPU reference (another jax, another CPU; its start window is used for the
learned rollout). Tolerances (module constants) and why:

* early, per particle: at most ``EARLY_TOLERANCE_M`` = 1e-5 m (a tenth of a
  percent of a cell), before rounding differences have grown; a 1-ulp shift
  of the start moves particles by 4e-7 m there.
* final, the MPM: RMS over particles at most 1 mm, any particle at most 1 cm
  (one grid cell), and the 1% front and the centre of mass within 1 mm. A
  1-ulp shift of every start position on this CPU moves the final particles
  by 4e-5 m RMS and 2e-4 m at most (measured in the reference, the
  ``envelope``); an accelerator rounds differently in every one of 8,400
  substeps (scatter order, fused multiply-adds, its own log and sqrt), so
  tens of times that are rounding; a difference in the physics moves sand
  by cells.
* final, the learned rollout: the 1% front and the centre of mass within
  1 mm. Its particles are not compared at the end: the same 1-ulp shift of
  its start moves single particles by up to 1.4 cm (RMS 3 mm) after 194
  steps on this CPU, while its front and centre move by under 0.1 mm.
  The accelerator's default float32 matmul precision may be TF32; the
  rollout is also run at ``highest`` and both are reported.

Timing follows ``timing``'s rules: compilation apart (``compile_s``), a
warm-up call, ``jax.block_until_ready`` (or the library's own synchronised
clock), medians of repeats, calls compared with each other interleaved.
Where a CPU size runs fewer frames or steps than the trajectory, the
seconds per trajectory are extrapolated per substep or step and marked so.
"""

import base64
import csv
import dataclasses
import functools
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
from typing import Any, Callable, Sequence

from absl import logging
import jax
import jax.numpy as jnp
import numpy as np

from experiments import timing
from experiments.benchmarks import gpu_report
from experiments.benchmarks.gpu_report import AGREEMENT_EARLY_FRAME
from experiments.benchmarks.gpu_report import EARLY_TOLERANCE_M
from experiments.benchmarks.gpu_report import FINAL_MAX_TOLERANCE_M
from experiments.benchmarks.gpu_report import FINAL_MEASURE_TOLERANCE_M
from experiments.benchmarks.gpu_report import FINAL_RMS_TOLERANCE_M
from experiments.benchmarks.gpu_report import GNS_EARLY_STEP
from experiments.benchmarks.gpu_report import PAPER_DATASET
from experiments.benchmarks.gpu_report import PAPER_TRAINING_H
from experiments.benchmarks import gns_programs
from experiments.benchmarks import scenes
from experiments.studies import settings
from experiments.studies import tradeoff as tradeoff_study
from gnsjax import metrics
from gnsjax import rollout as rollout_lib
from gnsjax import run as run_lib
from gnsjax import simulator
from gnsjax import train
import mpm
from mpm import dataset as mpm_dataset
from mpm import io as mpm_io
from mpm import batch_sizing
from mpm import simulation

PARTS = ("mpm", "gns", "train")
DEFAULT_REFERENCE = "docs/benchmarks/gpu_cpu_reference.json"
PRETRAINED = settings.PRETRAINED

MEASURES = ("front_1pct_m", "centre_x_m", "centre_y_m")


@dataclasses.dataclass(frozen=True)
class Sizes:
  """What to measure, and how much.

  Attributes:
    frames: frames of the paper trajectory (600).
    repeats: timed repeats of each one-at-a-time figure.
    batch_sizes: copies of the paper scene per vmapped call.
    batch_frames: frames each vmapped call runs (the trajectory's on an
      accelerator; fewer on the CPU, extrapolated).
    batch_repeats: timed repeats of each batch.
    chunk_frames: frames per compiled call (``mpm.simulate``'s 50).
    max_batch: run the batch ``batch_size_for`` picks (capped here).
    dataset_batch: dataset scenes per timed batch; dataset_frames: their
      frames (extrapolated to 600).
    spacings: particle spacings (m) of the speed/accuracy study's MPM rows.
    gns_config: config of the timed model (``experiments/configs``).
    gns_steps: learned steps per timed rollout (0: the whole trajectory).
    gns_batch_sizes: copies per vmapped rollout (1: ``rollout.rollout``).
    gns_repeats: timed repeats of each rollout.
    small_frames: frames of the small model's scene (its agreement and
      timing).
    train_config: config of the timed training.
    train_trajectories: training trajectories generated for it, of
      ``train_frames`` frames.
    train_warmup: steps before the timed ones; train_steps: timed steps,
      logged every ``train_log_every``.
  """
  frames: int = 600
  repeats: int = 3
  batch_sizes: tuple[int, ...] = (1, 8, 64, 256)
  batch_frames: int = 600
  batch_repeats: int = 2
  chunk_frames: int = 50
  max_batch: int = 4096
  dataset_batch: int = 64
  dataset_frames: int = 600
  spacings: tuple[float, ...] = (0.02, 0.01, 0.007, 0.005, 0.0035, 0.0025)
  gns_config: str = "paper"
  gns_steps: int = 0
  gns_batch_sizes: tuple[int, ...] = (1, 8, 32)
  gns_repeats: int = 2
  small_frames: int = 600
  train_config: str = "paper"
  train_trajectories: int = 2
  train_frames: int = 600
  train_warmup: int = 50
  train_steps: int = 200
  train_log_every: int = 25


# On an accelerator: whole trajectories everywhere.
FULL = Sizes()
# This project's CPU (one core, minutes): the same programs, short runs.
REFERENCE = Sizes(batch_frames=5, batch_repeats=2, chunk_frames=5,
                  max_batch=8, dataset_batch=8, dataset_frames=11,
                  gns_steps=5, gns_batch_sizes=(1, 8), gns_repeats=2,
                  train_trajectories=1, train_frames=100, train_warmup=2,
                  train_steps=6, train_log_every=2)
# Tiny sizes that exercise every measurement in seconds (smoke tests).
# Few distinct programs: the paper scene at its own spacing is the study's
# row, the largest batch reuses the x2 program, the test model's scene is
# the small model's (19 frames: 16 to start from, 1 learned step).
QUICK = Sizes(frames=19, repeats=1, batch_sizes=(1, 2), batch_frames=3,
              batch_repeats=1, chunk_frames=2, max_batch=2, dataset_batch=2,
              dataset_frames=3, spacings=(0.005,), gns_config="test",
              gns_steps=2, gns_batch_sizes=(1, 2), gns_repeats=1,
              small_frames=19, train_config="test", train_trajectories=1,
              train_frames=10, train_warmup=1, train_steps=2,
              train_log_every=1)


def sizes_for(accelerator: bool, quick: bool) -> Sizes:
  """QUICK, else FULL on an accelerator and REFERENCE on the CPU."""
  if quick:
    return QUICK
  return FULL if accelerator else REFERENCE


def stem_for(accelerator: bool) -> str:
  """``gpu`` on an accelerator, ``gpu_cpu`` on the CPU (the reference)."""
  return "gpu" if accelerator else "gpu_cpu"


def report_name(accelerator: bool) -> str:
  return "gpu_benchmark" if accelerator else "gpu_cpu_reference"


# ------------------------------------------------------------- helpers ---


def encode_positions(x: np.ndarray) -> dict[str, Any]:
  """float32 positions as JSON: shape and base64 of the bytes."""
  x = np.ascontiguousarray(x, np.float32)
  return {"shape": list(x.shape),
          "float32_base64": base64.b64encode(x.tobytes()).decode("ascii")}


def decode_positions(d: dict[str, Any]) -> np.ndarray:
  return np.frombuffer(base64.b64decode(d["float32_base64"]),
                       np.float32).reshape(d["shape"])


def paper_scene(num_frames: int) -> mpm.Scene:
  return mpm.Scene.from_dict({**scenes.PAPER_SCENE, "num_frames": num_frames})


def measures(x: np.ndarray) -> dict[str, float]:
  """Where the sand of one frame [N, 2] (m) is: the 1% front (it flows
  toward smaller x, ``metrics.runout``) and the centre of mass."""
  x = np.asarray(x, np.float64)
  return {"front_1pct_m": float(metrics.runout(x)),
          "centre_x_m": float(np.mean(x[:, 0])),
          "centre_y_m": float(np.mean(x[:, 1]))}


def difference(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
  """Per-particle distances of two frames [N, 2] (m) and the measures'."""
  d = np.linalg.norm(np.asarray(a, np.float64) - np.asarray(b, np.float64),
                     axis=-1)
  ma, mb = measures(a), measures(b)
  return {"max_m": float(d.max()), "rms_m": float(np.sqrt(np.mean(d**2))),
          "median_m": float(np.median(d)),
          **{k: abs(ma[k] - mb[k]) for k in MEASURES}}


def one_ulp(window: np.ndarray) -> np.ndarray:
  """Positions [..., 2] with every x moved up by one float32 ulp."""
  w = np.array(window, np.float32)
  w[..., 0] = np.nextafter(w[..., 0], np.float32(np.inf))
  return w


def _is_out_of_memory(e: Exception) -> bool:
  return "RESOURCE_EXHAUSTED" in str(e) or "out of memory" in str(e).lower()


# ------------------------------------------------------------------ mpm ---

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
    s = mpm.setup(scene, one_ulp(x0))
  return mpm.simulate_setups([s])[0].positions[list(frames)]


def agreement_frames(sizes: Sizes) -> list[int]:
  return [min(AGREEMENT_EARLY_FRAME, sizes.frames - 1), sizes.frames - 1]


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
  frames = agreement_frames(sizes)
  out["agreement"] = {"frames": frames,
                      "positions": encode_positions(first.positions[frames])}
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


# ------------------------------------------------------------------ gns ---


def still_decoder(params, hidden_layers: int):
  """``params`` with the decoder's last layer (kernel and bias) zero."""
  last = f"dense_{hidden_layers}"

  def zero(path, x):
    keys = [getattr(k, "key", None) for k in path]
    return jnp.zeros_like(x) if "decoder" in keys and last in keys else x
  return jax.tree_util.tree_map_with_path(zero, params)


def paper_problem(config, positions: np.ndarray,
                  scene: mpm.Scene) -> run_lib.Problem:
  """The problem of a config on one trajectory [T, N, 2]: its finite
  differences as statistics, the scene's domain, the dataset's radius."""
  fd = mpm_io.finite_difference_stats([positions],
                                      config.train.frame_stride)
  return run_lib.problem_from_dict(config, {
      **{k: np.asarray(v).tolist() for k, v in fd.items()},
      "bounds": [[0.0, scene.domain.width], [0.0, scene.domain.height]],
      "radius": float(config.model.connectivity_radius or
                      config.dataset.connectivity_radius),
      "noise_std": 0.0})


def measure_gns(sizes: Sizes, log: Callable[[str], None],
                save: Callable[[dict], None],
                twin: Callable[[str], dict] | None,
                reference: dict | None) -> dict[str, Any]:
  """The gns part: rollouts of the paper trajectory alone and batched, the
  small model on its scene, and the agreement of its rollout; ``save`` is
  called with what is measured so far after the rollouts."""
  config = gns_programs.load_config(sizes.gns_config)
  # The paper scene at the config's dataset spacing (the paper's: itself).
  scene = tradeoff_study.at_spacing(paper_scene(sizes.frames),
                            float(config.dataset.spacing))
  result = mpm.simulate(scene)
  problem = paper_problem(config, result.positions, scene)
  model = run_lib.create_model(config.model)
  params = still_decoder(gns_programs.init_params(model),
                         config.model.hidden_layers)
  c, k = problem.input_frames, problem.frame_stride
  start = rollout_lib.trajectory_nodes(
      mpm_io.Trajectory.from_result(result), c, k,
      problem.boundary_particles, problem.sdf_spacing)
  full = len(rollout_lib.predicted_frame_indices(sizes.frames, c, k))
  steps = min(sizes.gns_steps or full, full)
  chunk = min(50, steps)
  predictor = simulator.ModelPredictor(model)
  calls = {}
  for b in sizes.gns_batch_sizes:
    if b == 1:
      calls[b] = lambda: rollout_lib.rollout(
          predictor, params, start, steps, problem.context, problem.spec,
          chunk=chunk)
    else:
      calls[b] = lambda b=b: rollout_lib.rollout_batch(
          predictor, params, [start] * b, steps, problem.context,
          problem.spec, chunk=chunk)
  times = timing.time_calls({str(b): f for b, f in calls.items()},
                            sizes.gns_repeats)
  out: dict[str, Any] = {
      "model": {"config": sizes.gns_config,
                "latent_size": config.model.latent_size,
                "num_message_passing_steps":
                    config.model.num_message_passing_steps,
                "boundary_particles": problem.boundary_particles,
                "parameters": "initial, decoder's last layer zero"},
      "scene": {"name": scene.name, "n_sand": int(result.positions.shape[1]),
                "n_nodes": int(start.window.shape[1]),
                "frames": sizes.frames, "learned_steps": full,
                "steps_run": steps, "radius_m": problem.radius},
      "rollouts": []}
  for b in sizes.gns_batch_sizes:
    t = times[str(b)]
    row = {"batch": b, **t,
           "s_per_simulation": t["median_s"] / b * full / steps,
           "steps_per_s": steps / t["median_s"],
           "extrapolated": steps < full,
           "compile_and_warmup_s": t["warmup_s"]}
    out["rollouts"].append(row)
    log(f"{sizes.gns_config} model rollout x{b}: {t['median_s']:.3f} s for "
        f"{steps} steps -> {row['s_per_simulation']:.4f} s per simulation"
        + (" (extrapolated)" if row["extrapolated"] else ""))
  save(out)
  out["small_model"] = measure_small_model(sizes, log, twin, reference)
  return out


@functools.lru_cache(maxsize=1)
def small_model_start(frames: int):
  """The shipped small model, its scene (the paper scene at its dataset's
  spacing, 10 mm), that scene's start and the learned steps to 600.

  Computed once per process (the timing, the twin and the envelope start
  from the same window)."""
  run = run_lib.load_run(PRETRAINED)
  p = run.problem
  spacing = float(run.config.dataset.spacing)
  scene = tradeoff_study.at_spacing(paper_scene(frames), spacing)
  result = mpm.simulate(scene)
  start = rollout_lib.trajectory_nodes(
      mpm_io.Trajectory.from_result(result), p.input_frames, p.frame_stride,
      p.boundary_particles, p.sdf_spacing)
  steps = len(rollout_lib.predicted_frame_indices(frames, p.input_frames,
                                                  p.frame_stride))
  return run, scene, start, steps


def small_rollout(run, start, steps: int, window: np.ndarray | None = None
                  ) -> np.ndarray:
  """Sand positions [T, N, 2] of the small model's rollout (from
  ``window`` in place of the start's, if given)."""
  if window is not None:
    start = start._replace(window=np.asarray(window, np.float32))
  out = rollout_lib.rollout(simulator.ModelPredictor(run.model), run.params,
                            start, steps, run.problem.context,
                            run.problem.spec)
  return out.positions[:, np.asarray(start.moving)]


def gns_agreement_steps(steps: int) -> list[int]:
  return [min(GNS_EARLY_STEP, steps) - 1, steps - 1]


def measure_small_model(sizes: Sizes, log: Callable[[str], None],
                        twin: Callable[[str], dict] | None,
                        reference: dict | None) -> dict[str, Any]:
  """The small model's rollout timed on its scene, and compared with the
  CPU twin's (same start window) and the CPU reference's (its window)."""
  run, scene, start, steps = small_model_start(sizes.small_frames)
  at = gns_agreement_steps(steps)
  last = []   # the timed rollouts' positions (deterministic: all the same)

  def rollout():
    last[:] = [small_rollout(run, start, steps)]
    return last[0]

  timed = timing.time_calls({"small": rollout}, sizes.repeats)["small"]
  out = {"particles": scene.granular.num_particles, "steps": steps,
         "frame_stride": run.problem.frame_stride,
         "s_per_simulation": timed["median_s"], **timed,
         "agreement": {"steps": at,
                       "window": encode_positions(start.window),
                       "positions": encode_positions(last[0][at])}}
  log(f"small model on its scene ({out['particles']} particles, {steps} "
      f"steps): {timed['median_s']:.3f} s per simulation")
  if twin is not None:
    cpu = twin("gns")
    w = decode_positions(cpu["window"])
    runs = {"default": small_rollout(run, start, steps, w)}
    with jax.default_matmul_precision("highest"):
      runs["highest"] = small_rollout(run, start, steps, w)
    out["agreement"]["twin"] = {
        "envelope": compare(decode_positions(cpu["positions"]),
                            decode_positions(cpu["perturbed"]), "gns"),
        **{prec: compare(x[at], decode_positions(cpu["positions"]), "gns")
           for prec, x in runs.items()}}
  ref = _reference_part(reference, "gns")
  if ref is not None:
    r = ref["small_model"]["agreement"]
    if r["steps"] == at:
      # At the CPU's precision: an accelerator's default float32 matmul may
      # be TF32, which the twin's "default" row shows apart.
      with jax.default_matmul_precision("highest"):
        x = small_rollout(run, start, steps, decode_positions(r["window"]))
      out["agreement"]["reference"] = {
          **compare(x[at], decode_positions(r["positions"]), "gns"),
          "precision": "highest"}
  return out


# ---------------------------------------------------------------- train ---


def measure_training(sizes: Sizes, log: Callable[[str], None],
                     workdir: str) -> dict[str, Any]:
  """The train part: a dataset of the config's kind, then
  ``train.train_and_evaluate`` for warm-up + timed steps (evaluation off,
  one checkpoint at the end), its logged steps per second."""
  config = gns_programs.load_config(sizes.train_config)
  d = config.dataset
  spec = mpm_dataset.DatasetSpec(num_train=sizes.train_trajectories,
                                 num_test=1, num_frames=sizes.train_frames,
                                 seed=d.seed, spacing=d.spacing,
                                 connectivity_radius=d.connectivity_radius)
  data_dir = os.path.join(workdir, "data")
  _, gen_s = timing.wall(lambda: mpm_dataset.generate(spec, data_dir,
                                                      workers=1))
  total = sizes.train_warmup + sizes.train_steps
  config.train.num_steps = total
  config.log_every = sizes.train_log_every
  config.eval.every_steps = 0
  config.checkpoint.every_steps = 10 * total
  config.checkpoint.named_steps = ()
  config.checkpoint.keep = 1
  run_dir = os.path.join(workdir, "run")
  _, wall_s = timing.wall(lambda: train.train_and_evaluate(config, data_dir,
                                                           run_dir))
  with open(os.path.join(run_dir, "metrics.csv")) as f:
    rows = [{"step": int(r["step"]), "steps_per_s": float(r["steps_per_s"]),
             "wall_time_s": float(r["wall_time_s"])}
            for r in csv.DictReader(f)]
  timed = [r for r in rows if r["step"] > sizes.train_warmup]
  rate = statistics.median(r["steps_per_s"] for r in timed)
  at_warmup = [r for r in rows if r["step"] <= sizes.train_warmup]
  t0 = at_warmup[-1]["wall_time_s"] if at_warmup else 0.0
  overall = (timed[-1]["step"] - (at_warmup[-1]["step"] if at_warmup else 0)
             ) / (timed[-1]["wall_time_s"] - t0)
  out = {"config": sizes.train_config, "batch_size": config.train.batch_size,
         "latent_size": config.model.latent_size,
         "num_message_passing_steps":
             config.model.num_message_passing_steps,
         "dataset": {"trajectories": sizes.train_trajectories,
                     "frames": sizes.train_frames, "generate_s": gen_s},
         "warmup_steps": sizes.train_warmup, "timed_steps": sizes.train_steps,
         "log_every": sizes.train_log_every, "intervals": timed,
         "steps_per_s": rate, "steps_per_s_overall": overall,
         "run_wall_s": wall_s,
         "projected_h": {str(s): s / rate / 3600 for s in PAPER_TRAINING_H}}
  log(f"training ({sizes.train_config} config, batch "
      f"{config.train.batch_size}): {rate:.3g} steps/s (median of "
      f"{len(timed)} intervals of {sizes.train_log_every}; overall "
      f"{overall:.3g}) -> 1.5 M steps in "
      f"{out['projected_h']['1500000']:.3g} h")
  return out


# ------------------------------------------------------------ agreement ---


def compare(x: np.ndarray, ref: np.ndarray, kind: str) -> dict[str, Any]:
  """This device's positions [2, N, 2] (early, final) against a CPU's.

  Returns:
    The differences at each, and whether each tolerance holds (the
    per-particle final ones only for the MPM, see the module docstring).
  """
  early, final = difference(x[0], ref[0]), difference(x[-1], ref[-1])
  checks = {"early_max": early["max_m"] <= EARLY_TOLERANCE_M,
            **{f"final_{k}": final[k] <= FINAL_MEASURE_TOLERANCE_M
               for k in MEASURES}}
  if kind == "mpm":
    checks["final_rms"] = final["rms_m"] <= FINAL_RMS_TOLERANCE_M
    checks["final_max"] = final["max_m"] <= FINAL_MAX_TOLERANCE_M
  return {"early": early, "final": final, "checks": checks,
          "agrees": all(checks.values())}


def twin_positions(kind: str, sizes: Sizes) -> dict[str, Any]:
  """What the CPU twin computes (on this process's device): for "mpm" the
  paper scene at the agreement frames, unperturbed and 1 ulp to the right;
  for "gns" the small model's start window and its rollout at the
  agreement steps, from it and from it 1 ulp to the right."""
  if kind == "mpm":
    scene, frames = paper_scene(sizes.frames), agreement_frames(sizes)
    return {"positions": encode_positions(mpm_positions(scene, frames)),
            "perturbed": encode_positions(mpm_positions(scene, frames,
                                                        perturb=True))}
  run, _, start, steps = small_model_start(sizes.small_frames)
  at = gns_agreement_steps(steps)
  return {"window": encode_positions(start.window),
          "positions": encode_positions(small_rollout(run, start, steps)[at]),
          "perturbed": encode_positions(small_rollout(
              run, start, steps, one_ulp(start.window))[at])}


def run_twin(kind: str, quick: bool, workdir: str) -> dict[str, Any]:
  """``twin_positions`` in a child process on this machine's CPU
  (``JAX_PLATFORMS=cpu``, the same jax)."""
  path = os.path.join(workdir, f"twin_{kind}.json")
  env = {**os.environ, "JAX_PLATFORMS": "cpu"}
  subprocess.run([sys.executable, "-m", "experiments.benchmarks.gpu_benchmark",
                  "twin", kind, "quick" if quick else "full", path],
                 check=True, env=env)
  with open(path) as f:
    return json.load(f)


def _reference_part(reference: dict | None, part: str) -> dict | None:
  if not reference:
    return None
  return reference.get("parts", {}).get(part)


def mpm_agreement(out: dict, sizes: Sizes, twin, reference: dict | None,
                  envelope_here: bool) -> None:
  """Adds the MPM's comparisons to ``out["agreement"]``: against the twin
  (with its envelope), against the reference, and (on the CPU, where this
  process is the reference) the envelope of this device."""
  a = out["agreement"]
  mine = decode_positions(a["positions"])
  scene = paper_scene(sizes.frames)
  if envelope_here:
    a["envelope"] = compare(mine, mpm_positions(scene, a["frames"],
                                                perturb=True), "mpm")
  if twin is not None:
    cpu = twin("mpm")
    a["twin"] = {"envelope": compare(decode_positions(cpu["positions"]),
                                     decode_positions(cpu["perturbed"]),
                                     "mpm"),
                 "default": compare(mine, decode_positions(cpu["positions"]),
                                    "mpm")}
  ref = _reference_part(reference, "mpm")
  if ref is not None and ref["agreement"]["frames"] == a["frames"]:
    a["reference"] = compare(
        mine, decode_positions(ref["agreement"]["positions"]), "mpm")


def gns_envelope_here(out: dict, sizes: Sizes) -> None:
  """On the CPU: the small model's envelope (a 1-ulp shift of its start)."""
  s = out["small_model"]
  run, _, start, steps = small_model_start(sizes.small_frames)
  shifted = small_rollout(run, start, steps, one_ulp(start.window))
  s["agreement"]["envelope"] = compare(
      decode_positions(s["agreement"]["positions"]),
      shifted[s["agreement"]["steps"]], "gns")


# --------------------------------------------------------------- driver ---


def load_reference(path: str | None) -> dict | None:
  """The CPU reference report (None: no path, or no such file)."""
  if not path or not os.path.exists(path):
    return None
  with open(path) as f:
    return json.load(f)


def is_accelerator() -> bool:
  return jax.default_backend() != "cpu"


def run_part(part: str, out_dir: str, *, quick: bool = False,
             reference: dict | None = None, command: str = "",
             accelerator: bool | None = None,
             log: Callable[[str], None] = logging.info) -> str:
  """Measures one part on this process's first device and writes
  ``<stem>_<part>[_quick].json`` to ``out_dir``; returns its path.

  ``accelerator`` (default: whether the first device is not a CPU) picks
  the role: sizes, file names, and the comparisons with a CPU twin
  process and ``reference`` (tests take the accelerator's path on the
  CPU). The file is rewritten after each measurement with what is
  measured so far and ``"complete": false``, and with ``true`` at the end:
  a part stopped by a time limit keeps its finished rows."""
  if part not in PARTS:
    raise ValueError(f"part {part!r}; allowed: {PARTS}")
  if accelerator is None:
    accelerator = is_accelerator()
  sizes = sizes_for(accelerator, quick)
  results: dict[str, Any] = {
      "part": part, "command": command,
      "environment": timing.environment(quick, device_kind=jax.devices()[0]
                                        .device_kind),
      "sizes": dataclasses.asdict(sizes), "complete": False}
  os.makedirs(out_dir, exist_ok=True)
  path = os.path.join(out_dir, f"{stem_for(accelerator)}_{part}"
                      + ("_quick" if quick else "") + ".json")

  def save(measured: dict[str, Any]) -> None:
    # What is measured so far, so that a part stopped by a time limit keeps
    # its finished rows (the report marks it partial).
    results[part] = measured
    timing.write_json(path, results)

  with tempfile.TemporaryDirectory() as work:
    twin = ((lambda kind: run_twin(kind, quick, work)) if accelerator
            else None)
    if part == "mpm":
      measured = measure_mpm(sizes, log, save, lambda out: mpm_agreement(
          out, sizes, twin, reference, envelope_here=not accelerator))
    elif part == "gns":
      measured = measure_gns(sizes, log, save, twin, reference)
      if not accelerator:
        gns_envelope_here(measured, sizes)
    else:
      measured = measure_training(sizes, log, work)
  timing.end_environment(results["environment"])
  results["complete"] = True
  save(measured)
  return path


def read_parts(out_dir: str, accelerator: bool,
               quick: bool) -> dict[str, dict]:
  """The part files of one role found in ``out_dir``."""
  parts = {}
  suffix = "_quick" if quick else ""
  for part in PARTS:
    path = os.path.join(out_dir,
                        f"{stem_for(accelerator)}_{part}{suffix}.json")
    if os.path.exists(path):
      with open(path) as f:
        parts[part] = json.load(f)
  return parts


def write_report(out_dir: str, accelerator: bool, *, quick: bool = False,
                 reference: dict | None = None,
                 reference_path: str | None = None) -> dict[str, Any]:
  """Assembles the parts in ``out_dir`` with the reference into
  ``<report_name>[_quick].{json,md}``; returns the report (with
  "markdown" and "files").

  Raises:
    FileNotFoundError: no part file of this role in ``out_dir``.
  """
  parts = read_parts(out_dir, accelerator, quick)
  if not parts:
    raise FileNotFoundError(
        f"{out_dir}: no {stem_for(accelerator)}_<part>"
        f"{'_quick' if quick else ''}.json to report on (parts: {PARTS})")
  # A part stopped before its first measurement has nothing to report.
  parts = {k: v for k, v in parts.items() if k in v}
  report = {"accelerator": accelerator, "reference_file": reference_path,
            # The reference's parts ran on one machine: its first part's.
            "reference_environment": next(iter(
                (reference or {}).get("environments", {}).values()), None),
            "parts": {k: v[k] for k, v in parts.items()},
            "complete": {k: v.get("complete", True)
                         for k, v in parts.items()},
            "environments": {k: v["environment"] for k, v in parts.items()},
            "commands": {k: v["command"] for k, v in parts.items()},
            "summary": gpu_report.summarise(parts, reference)}
  timing.write_results(out_dir, report_name(accelerator), quick, report,
                       gpu_report.to_markdown(report, reference))
  return report


def run_benchmark(out_dir: str, *, parts: Sequence[str] = PARTS,
                  quick: bool = False, cpu_reference: str | None = None,
                  command: str = "", accelerator: bool | None = None,
                  log: Callable[[str], None] = logging.info
                  ) -> dict[str, Any]:
  """Runs ``parts`` (each written as it ends), then the report.

  Args:
    out_dir: directory of the part files and the report (created).
    parts: subset of ``PARTS``; none: only the report, from the parts
      already in ``out_dir``.
    quick: tiny sizes (``QUICK``), seconds: a smoke test, not figures.
    cpu_reference: the CPU reference report (``DEFAULT_REFERENCE``); on the
      CPU itself it is not read (this run is one).
    command: the command line, recorded.
    accelerator: the role (default: whether the first device is not a
      CPU; see ``run_part``).
    log: called with one line per measurement.

  Returns:
    The report (its JSON's content, "markdown" and "files").
  """
  if accelerator is None:
    accelerator = is_accelerator()
  reference = load_reference(cpu_reference) if accelerator else None
  if accelerator and reference is None:
    log(f"no CPU reference ({cpu_reference}): figures without ratios")
  for part in parts:
    path = run_part(part, out_dir, quick=quick, reference=reference,
                    command=command, accelerator=accelerator, log=log)
    log(f"wrote {path}")
  return write_report(out_dir, accelerator, quick=quick,
                      reference=reference,
                      reference_path=cpu_reference if reference else None)


def report_all(out_dir: str, *, quick: bool = False,
               cpu_reference: str | None = DEFAULT_REFERENCE
               ) -> list[dict[str, Any]]:
  """Rebuilds the report of each role whose part files are in
  ``out_dir`` (``--gpu_parts=report``): the accelerator's with the CPU
  reference, the CPU reference's. Measures nothing, needs no device.

  Raises:
    FileNotFoundError: no part file of either role in ``out_dir``.
  """
  reports = []
  for accelerator in (True, False):
    if read_parts(out_dir, accelerator, quick):
      reference = load_reference(cpu_reference) if accelerator else None
      reports.append(write_report(
          out_dir, accelerator, quick=quick, reference=reference,
          reference_path=cpu_reference if reference else None))
  if not reports:
    raise FileNotFoundError(
        f"{out_dir}: no gpu_<part>{'_quick' if quick else ''}.json nor "
        f"gpu_cpu_<part>{'_quick' if quick else ''}.json to report on")
  return reports


def _twin_main(argv: list[str]) -> None:
  """``python -m experiments.benchmarks.gpu_benchmark twin KIND SIZES
  PATH``: ``twin_positions`` written to PATH (JSON)."""
  _, kind, which, path = argv
  sizes = QUICK if which == "quick" else FULL
  mpm_io.write_text(path, json.dumps(twin_positions(kind, sizes)))


if __name__ == "__main__":
  _twin_main(sys.argv[1:])
