"""The GPU command's gns part: learned rollouts on this device, and agreement.

The paper model (``configs/paper.py``: latent 128, 10 message-passing
steps, boundary particles as nodes) rolling out the paper trajectory (594
learned steps after C = 6 input frames) alone and as B copies in one
vmapped rollout: seconds per simulation, the paper's Table 2 measure. The
model has its initial parameters with the decoder's last layer set to zero
(``still_decoder``), so it predicts the data's mean acceleration and the
sand stays close to its start: the graph keeps the dense heap's edges
(about the most a trajectory has) and every step does a trained model's
work, whose cost does not depend on the parameters' values. Also the
shipped small model (``experiments/pretrained/small``) on its own scene,
the learned row of the speed/accuracy study, and its rollout's agreement
with a CPU (``measure_small_model``; the tolerances and why:
``gpu_benchmark``).
"""

import functools
import hashlib
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from experiments import timing
from experiments.benchmarks import gns_programs
from experiments.benchmarks import gpu_agreement
from experiments.benchmarks import gpu_mpm
from experiments.benchmarks.gpu_report import GNS_EARLY_STEP
from experiments.benchmarks.gpu_sizes import Sizes
from experiments.studies import settings
from experiments.studies import tradeoff as tradeoff_study
from gnsjax import rollout as rollout_lib
from gnsjax import run as run_lib
from gnsjax import simulator
import mpm
from mpm import io as mpm_io

PRETRAINED = settings.PRETRAINED


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
  scene = tradeoff_study.at_spacing(gpu_mpm.paper_scene(sizes.frames),
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
  scene = tradeoff_study.at_spacing(gpu_mpm.paper_scene(frames), spacing)
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


def params_digest(params) -> str:
  """A short SHA-256 of the parameters' values: which model a stored
  rollout came from (a reference of another model is not compared)."""
  h = hashlib.sha256()
  for leaf in jax.tree.leaves(params):
    h.update(np.ascontiguousarray(np.asarray(leaf)).tobytes())
  return h.hexdigest()[:16]


def gns_agreement_steps(steps: int) -> list[int]:
  return [min(GNS_EARLY_STEP, steps) - 1, steps - 1]


def measure_small_model(sizes: Sizes, log: Callable[[str], None],
                        twin: Callable[[str], dict] | None,
                        reference: dict | None) -> dict[str, Any]:
  """The small model's rollout timed on its scene, and compared with the
  CPU twin's (same start window) and the CPU reference's (its window)."""
  compare, decode = gpu_agreement.compare, gpu_agreement.decode_positions
  encode = gpu_agreement.encode_positions
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
         "agreement": {"steps": at, "model_digest": params_digest(run.params),
                       "window": encode(start.window),
                       "positions": encode(last[0][at])}}
  log(f"small model on its scene ({out['particles']} particles, {steps} "
      f"steps): {timed['median_s']:.3f} s per simulation")
  if twin is not None:
    cpu = twin("gns")
    w = decode(cpu["window"])
    runs = {"default": small_rollout(run, start, steps, w)}
    with jax.default_matmul_precision("highest"):
      runs["highest"] = small_rollout(run, start, steps, w)
    out["agreement"]["twin"] = {
        "envelope": compare(decode(cpu["positions"]),
                            decode(cpu["perturbed"]), "gns"),
        **{prec: compare(x[at], decode(cpu["positions"]), "gns")
           for prec, x in runs.items()}}
  ref = gpu_agreement.reference_part(reference, "gns")
  if ref is not None:
    r = ref["small_model"]["agreement"]
    ours = out["agreement"]["model_digest"]
    if r.get("model_digest") != ours:
      # The shipped model changed since the reference was taken: its
      # rollout is another model's, and no figure is made of it.
      out["agreement"]["reference"] = {
          "skipped": f"the reference's rollout is of another model "
                     f"({r.get('model_digest', 'unrecorded')} against "
                     f"{ours}); take the CPU reference again"}
    elif r["steps"] == at:
      # At the CPU's precision: an accelerator's default float32 matmul may
      # be TF32, which the twin's "default" row shows apart.
      with jax.default_matmul_precision("highest"):
        x = small_rollout(run, start, steps, decode(r["window"]))
      out["agreement"]["reference"] = {
          **compare(x[at], decode(r["positions"]), "gns"),
          "precision": "highest"}
  return out


def gns_envelope_here(out: dict, sizes: Sizes) -> None:
  """On the CPU: the small model's envelope (a 1-ulp shift of its start)."""
  s = out["small_model"]
  run, _, start, steps = small_model_start(sizes.small_frames)
  shifted = small_rollout(run, start, steps,
                          gpu_agreement.one_ulp(start.window))
  s["agreement"]["envelope"] = gpu_agreement.compare(
      gpu_agreement.decode_positions(s["agreement"]["positions"]),
      shifted[s["agreement"]["steps"]], "gns")
