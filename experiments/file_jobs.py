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
from mpm import io as mpm_io


def simulate_to_file(scene: mpm.Scene, out: str, seed: int = -1,
                     chunk_frames: int = 50,
                     rest_speed: float | None = None) -> mpm.SimulationResult:
  """Simulates ``scene`` with a progress bar and writes the file ``out``
  (creating its directory); ``rest_speed`` as ``mpm.simulate_setups``'."""
  with tqdm.tqdm(total=scene.num_frames - 1, unit="frame",
                 desc=scene.name) as bar:
    result = mpm.simulate(scene, chunk_frames=chunk_frames,
                          progress=lambda done: bar.update(done - bar.n),
                          rest_speed=rest_speed)
  os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
  mpm_io.write_trajectories(out, [mpm_io.Trajectory.from_result(result, seed)])
  return result


def _nth(path: str, index: int) -> mpm_io.Trajectory:
  trajectories = list(mpm_io.read_trajectories(path))
  if not 0 <= index < len(trajectories):
    raise mpm.InputError(f"index={index}: {path} holds {len(trajectories)} "
                     f"trajectories; allowed: 0..{len(trajectories) - 1}")
  return trajectories[index]


def default_frames(num_frames: int, count: int = 6) -> list[int]:
  """``count`` frame indices from the first to the last (fewer if the
  trajectory is shorter): the grid shows the start and the deposit."""
  return sorted({int(f) for f in np.linspace(0, num_frames - 1, count).round()})


def _stem(path: str) -> str:
  return os.path.splitext(os.path.basename(path))[0]


def render_file(traj_path: str, out_dir: str, index: int = 0,
                frames: Sequence[int] | None = None,
                fmt: str = "gif",
                compare_path: str | None = None) -> tuple[str, str]:
  """Writes ``animation.<fmt>`` and ``frames.png`` for one trajectory, beside
  the same trajectory of ``compare_path`` if given (the paper's Fig. 2),
  each panel titled by its file's name (``truth``, ``predicted``). The
  grid's ``frames`` default to six from the first to the last."""
  from experiments import figures  # pylint: disable=g-import-not-at-top
  t = _nth(traj_path, index)
  n = len(t.positions)
  panels = [(f"{_stem(traj_path)}: {t.scene.name}", t.positions)]
  if compare_path is not None:
    other = _nth(compare_path, index)
    if other.positions.shape != t.positions.shape:
      raise mpm.InputError(f"{compare_path}: trajectory {index} has shape "
                           f"{other.positions.shape}, {traj_path} has "
                           f"{t.positions.shape}")
    panels.append((_stem(compare_path), other.positions))
  if frames is None:
    frames = default_frames(n)
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
