"""The file jobs behind the entry points, as plain functions (no flags):
simulate a scene to a trajectory file (``experiments.simulate``), render a
trajectory file (``experiments.render``), roll a trained run out into
trajectory files (``experiments.rollout``).

The demo study composes them. Plotting (matplotlib) and the learned
simulator (gnsjax) are imported only by the jobs that need them, so that
``python -m experiments.simulate`` loads neither.
"""

import dataclasses
import os
from typing import Sequence

import numpy as np
import tqdm

import mpm
from experiments.studies import settings as settings_lib
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
  from experiments import figures  # pylint: disable=g-import-not-at-top
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
  # pylint: disable=g-import-not-at-top
  from gnsjax import data
  from gnsjax import rollout as rollout_lib
  from gnsjax import run as run_lib
  # pylint: enable=g-import-not-at-top
  run = run_lib.load_run(workdir)
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
    predicted.append(with_frames(t, np.concatenate(
        [t.positions[inputs], out.positions]), k))
    truth.append(with_frames(t, t.positions[np.concatenate([inputs,
                                                             frames])], k))
  paths = {"predicted": os.path.join(out_dir, "predicted.h5"),
           "truth": os.path.join(out_dir, "truth.h5")}
  mpm_io.write_trajectories(paths["predicted"], predicted)
  mpm_io.write_trajectories(paths["truth"], truth)
  return paths


def with_frames(t: mpm_io.Trajectory, positions: np.ndarray,
                stride: int) -> mpm_io.Trajectory:
  """The trajectory with every ``stride``-th frame from 0 as ``positions``:
  its scene's frame count and frame_dt follow, so the file stays
  self-consistent."""
  scene = dataclasses.replace(t.scene, num_frames=len(positions),
                              frame_dt=t.scene.frame_dt * stride)
  return dataclasses.replace(t, positions=positions.astype(np.float32),
                             scene=scene)


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
                   workdir: str | None = settings_lib.PRETRAINED,
                   steps: int = 8,
                   learning_rate: float = 0.05, sweep_points: int = 9,
                   optimise_size: bool = False, method: str = "adam",
                   sigma: float = 0.05, num_samples: int = 16,
                   estimator: str = "score") -> dict:
  """The inverse-design study (``gnsjax.design.study.study``) of a scene,
  with its plot ``objective_vs_x.png``; returns the summary."""
  from experiments import figures  # pylint: disable=g-import-not-at-top
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
