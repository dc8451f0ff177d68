"""The jobs behind the entry points, as plain functions (no flags here).

Each ``experiments/<name>.py`` parses flags and calls one function of this
module, so that jobs compose (the demo runs several) and tests call them
directly.
"""

import dataclasses
import hashlib
import os
from typing import Sequence

import numpy as np
import tqdm

import mpm
from experiments import figures
from gnsjax import data
from mpm import io as mpm_io


def simulate_to_file(scene: mpm.Scene, out: str, seed: int = -1,
                     chunk_frames: int = 50) -> mpm.SimulationResult:
  """Simulates ``scene`` with a progress bar and writes the file ``out``
  (creating its directory)."""
  with tqdm.tqdm(total=scene.num_frames - 1, unit="frame",
                 desc=scene.name) as bar:
    result = mpm.simulate(scene, chunk_frames=chunk_frames,
                          progress=lambda done: bar.update(done - bar.n))
  os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
  mpm_io.write_trajectories(out, [mpm_io.Trajectory.from_result(result, seed)])
  return result


def _nth(path: str, index: int) -> mpm_io.Trajectory:
  trajectories = list(mpm_io.read_trajectories(path))
  if not 0 <= index < len(trajectories):
    raise mpm.InputError(f"index={index}: {path} holds {len(trajectories)} "
                     f"trajectories; allowed: 0..{len(trajectories) - 1}")
  return trajectories[index]


def render_file(traj_path: str, out_dir: str, index: int = 0,
                frames: Sequence[int] | None = None,
                fmt: str = "gif",
                compare_path: str | None = None) -> tuple[str, str]:
  """Writes ``animation.<fmt>`` and ``frames.png`` for one trajectory, beside
  the same trajectory of ``compare_path`` if given (the paper's Fig. 2: MPM
  left, GNS right). ``frames`` of the grid default to the paper's (1, 80,
  120, 180) that the trajectory has."""
  t = _nth(traj_path, index)
  n = len(t.positions)
  panels = [(f"MPM: {t.scene.name}", t.positions)]
  if compare_path is not None:
    other = _nth(compare_path, index)
    if other.positions.shape != t.positions.shape:
      raise mpm.InputError(f"{compare_path}: trajectory {index} has shape "
                           f"{other.positions.shape}, {traj_path} has "
                           f"{t.positions.shape}")
    panels.append(("GNS", other.positions))
  if frames is None:
    frames = [f for f in (1, 80, 120, 180) if f < n]
  elif not all(0 <= f < n for f in frames):
    raise mpm.InputError(f"frames {list(frames)}: {traj_path} trajectory "
                         f"{index} has {n} frames; allowed: comma-separated "
                         f"frame indices in [0, {n - 1}]")
  os.makedirs(out_dir, exist_ok=True)
  anim = figures.animate(panels, t.scene, t.boundary_positions,
                         t.boundary_type,
                         os.path.join(out_dir, f"animation.{fmt}"))
  grid = figures.frame_grid(panels, t.scene, t.boundary_positions,
                            t.boundary_type, frames,
                            os.path.join(out_dir, "frames.png"))
  return anim, grid


def rollout_to_files(workdir: str, data_dir: str, out_dir: str,
                     split: str = "test",
                     max_trajectories: int | None = None,
                     project: bool = True) -> dict[str, str]:
  """Rolls out a split with a trained run; writes predicted and true files.

  Both files hold the frames the model predicts (every ``frame_stride``-th
  stored frame after the inputs), preceded by its input frames.
  """
  from gnsjax import rollout as rollout_lib  # pylint: disable=g-import-not-at-top
  from gnsjax import train  # pylint: disable=g-import-not-at-top
  run = train.load_run(workdir)
  path = data.split_path(data_dir, split)
  os.makedirs(out_dir, exist_ok=True)
  c, k = run.problem.input_frames, run.problem.frame_stride
  predicted, truth = [], []
  for i, t in enumerate(tqdm.tqdm(list(data.trajectories(path)),
                                  unit="traj", desc="rollout")):
    if max_trajectories is not None and i >= max_trajectories:
      break
    inputs = rollout_lib.input_frame_indices(c, k)
    frames = rollout_lib.predicted_frame_indices(len(t.positions), c, k)
    out = rollout_lib.rollout_trajectory(run.model, run.params, t,
                                         run.problem, project=project)
    predicted.append(_with_frames(t, np.concatenate(
        [t.positions[inputs], out.positions]), k))
    truth.append(_with_frames(t, t.positions[np.concatenate([inputs,
                                                             frames])], k))
  paths = {"predicted": os.path.join(out_dir, "predicted.h5"),
           "truth": os.path.join(out_dir, "truth.h5")}
  mpm_io.write_trajectories(paths["predicted"], predicted)
  mpm_io.write_trajectories(paths["truth"], truth)
  return paths


def _with_frames(t: mpm_io.Trajectory, positions: np.ndarray, stride: int):
  """The trajectory with every ``stride``-th frame from 0 as ``positions``:
  its scene's frame count and frame_dt follow, so the file stays
  self-consistent."""
  scene = dataclasses.replace(t.scene, num_frames=len(positions),
                              frame_dt=t.scene.frame_dt * stride)
  return dataclasses.replace(t, positions=positions.astype(np.float32),
                             scene=scene)


# A small pretrained model shipped with the project (experiments/configs/
# small.py); see its provenance.json.
PRETRAINED = os.path.join(os.path.dirname(__file__), "pretrained", "small")


def demo_config(num_train: int, num_test: int, steps: int,
                num_frames: int = 600):
  """configs/small.py with a demo-sized dataset and a short training."""
  from experiments.configs import small  # pylint: disable=g-import-not-at-top
  config = small.get_config()
  config.dataset.num_frames = num_frames
  config.dataset.num_train = num_train
  config.dataset.num_test = num_test
  config.train.num_steps = steps
  # A constant small rate, whatever step the shipped model stopped at: a
  # short fine-tuning on a few scenes should adjust it, not retrain it.
  config.train.lr_init = config.train.lr_min = 1.5e-5
  config.checkpoint.every_steps = 100
  config.checkpoint.named_steps = ()
  config.eval.every_steps = 0
  return config


# In a demo's work directory: which shipped checkpoint it was started from.
SHIPPED_RECORD = "shipped_from.json"


def ship_checkpoint(source: str, workdir: str) -> int:
  """Copies a shipped checkpoint into ``workdir``; returns its step.

  A work directory started from another shipped checkpoint (an older model,
  before an update) would resume its own run and silently show the old
  model, so it is refused.

  Raises:
    mpm.InputError: when ``workdir`` holds checkpoints not started from this
      one (it names what to delete).
  """
  import shutil  # pylint: disable=g-import-not-at-top
  steps = sorted(int(d) for d in os.listdir(os.path.join(source, "checkpoints"))
                 if d.isdigit())
  with open(os.path.join(source, "provenance.json"), "rb") as f:
    shipped = {"step": steps[-1],
               "provenance_sha256": hashlib.sha256(f.read()).hexdigest()}
  record = os.path.join(workdir, SHIPPED_RECORD)
  held = os.path.join(workdir, "checkpoints")
  if os.path.isdir(held) and os.listdir(held):
    previous = mpm_io.read_json(record) if os.path.exists(record) else None
    if previous != shipped:
      raise mpm.InputError(
          f"{workdir} holds a run started from another shipped model (or "
          f"from none); delete {workdir} (or choose another --out) to start "
          "from the current one")
  # The record first: a kill between the two leaves a record and no
  # checkpoint, which the next run accepts.
  os.makedirs(workdir, exist_ok=True)
  mpm_io.write_json(record, shipped)
  target = os.path.join(held, str(steps[-1]))
  if not os.path.exists(target):
    # Copied whole or not at all: a half copy would pass for a checkpoint.
    partial = target + ".partial"
    shutil.rmtree(partial, ignore_errors=True)
    shutil.copytree(os.path.join(source, "checkpoints", str(steps[-1])),
                    partial)
    os.replace(partial, target)
  return steps[-1]


def demo(out_dir: str, *, num_train: int = 4, num_test: int = 6,
         num_frames: int = 600, finetune_steps: int = 200,
         pretrained: str | None = PRETRAINED,
         workers: int = 2) -> dict[str, str]:
  """The end-to-end demo: data, model, rollout of an unseen scene, pictures.

  1. Generates a small dataset (the small config's physics, few scenes).
  2. Fine-tunes the shipped pretrained small model on it for
     ``finetune_steps`` steps (or, without one, trains from scratch).
  3. Rolls the model out on the test scene with the triangle obstacle, a
     shape never seen in training, and measures it against the MPM and a
     constant-velocity baseline.
  4. Writes the metrics and an MPM | GNS animation and frame grid.
  """
  from experiments.studies import evaluation  # pylint: disable=g-import-not-at-top
  from gnsjax import rollout as rollout_lib  # pylint: disable=g-import-not-at-top
  from gnsjax import train  # pylint: disable=g-import-not-at-top
  from mpm import dataset  # pylint: disable=g-import-not-at-top

  os.makedirs(out_dir, exist_ok=True)
  data_dir = os.path.join(out_dir, "data")
  workdir = os.path.join(out_dir, "run")
  os.makedirs(workdir, exist_ok=True)
  start = 0
  if pretrained and os.path.isdir(os.path.join(pretrained, "checkpoints")):
    start = ship_checkpoint(pretrained, workdir)
  config = demo_config(num_train, num_test, start + finetune_steps,
                       num_frames)
  spec = dataset.DatasetSpec(**config.dataset.to_dict())
  with tqdm.tqdm(total=spec.num_train + spec.num_test, unit="traj",
                 desc="dataset") as bar:
    dataset.generate(spec, data_dir, workers=workers,
                     progress=lambda done, *_: bar.update(done - bar.n))
  train.train_and_evaluate(config, data_dir, workdir)

  run = train.load_run(workdir)
  c, k = run.problem.input_frames, run.problem.frame_stride
  t = next(t for t in data.trajectories(data.split_path(data_dir, "test"))
           if dataset.group_of(t.scene.name) == "triangle")
  frames = rollout_lib.predicted_frame_indices(len(t.positions), c, k)
  with tqdm.tqdm(total=1, unit="rollout", desc="GNS rollout") as bar:
    out = rollout_lib.rollout_trajectory(run.model, run.params, t,
                                         run.problem)
    bar.update(1)
  scores = evaluation.score(t, out, frames, run.problem)
  row = evaluation.per_trajectory_row({
      "index": 0, "name": t.scene.name, **evaluation.describe(t.scene),
      **scores})
  result = {
      "scene": t.scene.name, "model_step": run.step, "fine_tuned_from": start,
      "particles": int(t.positions.shape[1]), "learned_steps": len(frames),
      "frame_stride": k,
      "gns_mean_mse_m2": row["mean_mse"],
      "gns_final_mse_m2": row["final_mse"],
      "constant_velocity_mean_mse_m2": row["mean_mse_constant_velocity"],
      "gns_final_runout_error_m": row["final_runout_error"],
      "gns_front_error_relative": row["front_error_relative"],
      "gns_deposit_error_m": row["deposit_error"],
      "gns_max_inside_solids": row["max_inside_solids"],
      "gns_max_outside_domain": row["max_outside_domain"],
      "gns_final_speed_m_s": row["final_speed"],
      "mpm_final_speed_m_s": row["mpm_final_speed"],
      "mpm_max_inside_solids": row["mpm_max_inside_solids"],
      "gns_mean_pushed_fraction": row["mean_pushed_fraction"],
  }
  paths = {"data": data_dir, "run": workdir,
           "metrics": os.path.join(out_dir, "metrics.json"),
           "truth": os.path.join(out_dir, "truth.h5"),
           "predicted": os.path.join(out_dir, "predicted.h5")}
  mpm_io.write_json(paths["metrics"], result)
  inputs = rollout_lib.input_frame_indices(c, k)
  mpm_io.write_trajectories(paths["truth"], [_with_frames(
      t, t.positions[np.concatenate([inputs, frames])], k)])
  mpm_io.write_trajectories(paths["predicted"], [_with_frames(
      t, np.concatenate([t.positions[inputs], out.positions]), k)])
  shown = np.linspace(1, len(inputs) + len(frames) - 1, 5).astype(int)
  paths["animation"], paths["frames"] = render_file(
      paths["truth"], out_dir, frames=tuple(shown),
      compare_path=paths["predicted"])
  for k, value in result.items():
    print(f"{k:>32}: {value:.4g}" if isinstance(value, float) else
          f"{k:>32}: {value}")
  return paths


def design_scene(shape: str = "semicircle", size: Sequence[float] = (0.04,),
                 x0: float = 1.0, num_frames: int = 600,
                 spacing: float = 0.01, num_particles: int = 250
                 ) -> mpm.Scene:
  """The paper's heap at the small config's spacing with one obstacle."""
  from gnsjax.design import placement  # pylint: disable=g-import-not-at-top
  from mpm import scene as scene_lib  # pylint: disable=g-import-not-at-top
  keys = scene_lib.OBSTACLE_SHAPES[shape]
  if len(size) != len(keys):
    raise ValueError(f"size = {list(size)}: a {shape} needs {len(keys)} "
                     f"value(s), {list(keys)} (m)")
  base = mpm.Scene.from_dict({
      "name": f"design_{shape}",
      "granular": {"box": list(scene_lib.Granular.box), "spacing": spacing,
                   "num_particles": num_particles},
      "num_frames": num_frames})
  return placement.with_obstacle(base, shape, x0, **dict(zip(keys, size)))


def calibration_study(out_dir: str, *, truth: Sequence[float],
                      start: Sequence[float], methods: Sequence[str],
                      budget_s: float | None = None,
                      budget_evals: int | None = None,
                      num_frames: int = 600, spacing: float = 0.01,
                      num_particles: int = 250, learning_rate: float = 0.05,
                      batch_size: int = 8, sweep_points: int = 5,
                      seed: int = 0) -> dict:
  """Inverse analysis (``gnsjax.design.calibration.study``): the paper's
  heap, no obstacle, observed by the MPM at ``truth``; each method
  recovers the friction angle and basal friction from ``start``."""
  # pylint: disable=g-import-not-at-top
  from gnsjax.design import baselines
  from gnsjax.design import calibration
  from mpm import scene as scene_lib
  # pylint: enable=g-import-not-at-top
  scene = mpm.Scene.from_dict({
      "name": "calibrate",
      "granular": {"box": list(scene_lib.Granular.box), "spacing": spacing,
                   "num_particles": num_particles},
      "num_frames": num_frames})
  problem = calibration.Calibration.observe(scene, truth,
                                            batch_size=batch_size)
  return calibration.study(
      out_dir, problem, truth, start, methods,
      baselines.Budget(budget_evals, budget_s),
      log=lambda line: tqdm.tqdm.write(line), learning_rate=learning_rate,
      points=sweep_points, seed=seed)


def inverse_design(out_dir: str, *, scene_path: str | None = None,
                   shape: str = "semicircle", size: Sequence[float] = (0.04,),
                   x0: float = 1.0, num_frames: int = 600,
                   simulator: str = "gns", objective: str = "passed_fraction",
                   x_protect: float = 0.4, target_x: float = 0.6,
                   temperature: float | None = None,
                   workdir: str | None = PRETRAINED, steps: int = 8,
                   learning_rate: float = 0.05, sweep_points: int = 9,
                   optimise_size: bool = False, method: str = "adam",
                   sigma: float = 0.05, num_samples: int = 16,
                   estimator: str = "score") -> dict:
  """The inverse-design study (``gnsjax.design.study.study``) of a scene,
  with its plot ``objective_vs_x.png``; returns the summary."""
  from gnsjax.design import objectives  # pylint: disable=g-import-not-at-top
  from gnsjax.design import study  # pylint: disable=g-import-not-at-top
  if scene_path is not None:
    scene = mpm.Scene.load(scene_path)
  else:
    scene = design_scene(shape, size, x0, num_frames)
  obj = objectives.make(objective, x_protect=x_protect, target_x=target_x,
                        temperature=temperature)
  result = study.study(
      out_dir, scene, obj, simulator=simulator, workdir=workdir or None,
      steps=steps, learning_rate=learning_rate, sweep_points=sweep_points,
      optimise_size=optimise_size, method=method, sigma=sigma,
      num_samples=num_samples, estimator=estimator,
      log=lambda line: tqdm.tqdm.write(line))
  figures.objective_vs_x(result.sweep, result.history, obj.name, simulator,
                         os.path.join(out_dir, "objective_vs_x.png"),
                         smoothed=method == "adam_smoothed")
  return result.summary


def design_comparison(out_dir: str, *, problem: str = "two_obstacles",
                      methods: Sequence[str] = ("adam",),
                      budget_s: float | None = None,
                      budget_evals: int | None = None,
                      xs: Sequence[float] = (0.9, 1.1),
                      radii: Sequence[float] = (0.04, 0.04),
                      num_baffles: int = 5,
                      shape: str = "semicircle",
                      size: Sequence[float] = (0.04,), x0: float = 1.0,
                      optimise_size: bool = False, num_frames: int = 600,
                      objective: str = "passed_fraction",
                      x_protect: float = 0.4, target_x: float = 0.6,
                      temperature: float | None = None,
                      learning_rate: float = 0.05, sigma: float = 0.05,
                      num_samples: int = 16, batch_size: int = 8,
                      sweep_points: int = 3, seed: int = 0) -> dict:
  """Inverse design against the baselines at equal budget on the MPM
  (``gnsjax.design.comparison.compare``); returns the summary.

  ``problem``: "placement" (one obstacle, ``shape``/``size`` at ``x0``; x,
  and the size with ``optimise_size``), "two_obstacles" (two semicircles
  at ``xs`` of ``radii``; x and radius each, 4 parameters) or "baffles" (a
  row of ``num_baffles`` small rectangles; their x).
  """
  # pylint: disable=g-import-not-at-top
  from gnsjax.design import baselines
  from gnsjax.design import comparison
  from gnsjax.design import objectives
  from gnsjax.design import placement as placement_lib
  # pylint: enable=g-import-not-at-top
  if problem == "two_obstacles":
    placement = placement_lib.MultiPlacement(
        comparison.two_obstacles_scene(xs, radii, num_frames))
  elif problem == "baffles":
    placement = placement_lib.MultiPlacement(
        comparison.baffles_scene(num_baffles, num_frames),
        indices=tuple(range(num_baffles)), free=("x",))
  elif problem == "placement":
    placement = placement_lib.Placement(
        design_scene(shape, size, x0, num_frames),
        free=("x", "size") if optimise_size else ("x",))
  else:
    raise ValueError(f"problem: {problem!r}; allowed: "
                     f"{list(comparison.PROBLEMS)}")
  obj = objectives.make(objective, x_protect=x_protect, target_x=target_x,
                        temperature=temperature)
  return comparison.compare(
      out_dir, placement, obj, methods,
      baselines.Budget(budget_evals, budget_s), problem=problem,
      progress=lambda m: tqdm.tqdm(m, desc="methods", unit="method"),
      log=lambda line: tqdm.tqdm.write(line), learning_rate=learning_rate,
      sigma=sigma, num_samples=num_samples, batch_size=batch_size,
      sweep_points=sweep_points, seed=seed)
