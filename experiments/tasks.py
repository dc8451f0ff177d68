"""The jobs behind the entry points, as plain functions (no flags here).

Each ``experiments/<name>.py`` parses flags and calls one function of this
module, so that jobs compose (the demo runs several) and tests call them
directly.
"""

import dataclasses
import os
from typing import Sequence

import numpy as np
import tqdm

import mpm
from gnsjax import data
from gnsjax import render
from mpm import io as mpm_io


def simulate_to_file(scene: mpm.Scene, out: str, seed: int = -1,
                     chunk_frames: int = 50) -> mpm.SimulationResult:
  """Simulates ``scene`` with a progress bar and writes the file ``out``."""
  with tqdm.tqdm(total=scene.num_frames - 1, unit="frame",
                 desc=scene.name) as bar:
    result = mpm.simulate(scene, chunk_frames=chunk_frames,
                          progress=lambda done: bar.update(done - bar.n))
  mpm_io.write_trajectories(out, [mpm_io.Trajectory.from_result(result, seed)])
  return result


def _nth(path: str, index: int) -> mpm_io.Trajectory:
  trajectories = list(mpm_io.read_trajectories(path))
  if not 0 <= index < len(trajectories):
    raise ValueError(f"index={index}: {path} holds {len(trajectories)} "
                     f"trajectories; allowed: 0..{len(trajectories) - 1}")
  return trajectories[index]


def render_file(traj_path: str, out_dir: str, index: int = 0,
                frames: Sequence[int] = (1, 80, 120, 180),
                fmt: str = "gif",
                compare_path: str | None = None) -> tuple[str, str]:
  """Writes ``animation.<fmt>`` and ``frames.png`` for one trajectory, beside
  the same trajectory of ``compare_path`` if given (the paper's Fig. 2: MPM
  left, GNS right)."""
  t = _nth(traj_path, index)
  os.makedirs(out_dir, exist_ok=True)
  panels = [(f"MPM: {t.scene.name}", t.positions)]
  if compare_path is not None:
    other = _nth(compare_path, index)
    if other.positions.shape != t.positions.shape:
      raise ValueError(f"{compare_path}: trajectory {index} has shape "
                       f"{other.positions.shape}, {traj_path} has "
                       f"{t.positions.shape}")
    panels.append(("GNS", other.positions))
  frames = [f for f in frames if f < len(t.positions)]
  anim = render.animate(panels, t.scene, t.boundary_positions, t.boundary_type,
                        os.path.join(out_dir, f"animation.{fmt}"))
  grid = render.frame_grid(panels, t.scene, t.boundary_positions,
                           t.boundary_type, frames,
                           os.path.join(out_dir, "frames.png"))
  return anim, grid


def rollout_to_files(workdir: str, data_dir: str, out_dir: str,
                     split: str = "test",
                     max_trajectories: int | None = None) -> dict[str, str]:
  """Rolls out a split with a trained run; writes predicted and true files."""
  from gnsjax import evaluate  # pylint: disable=g-import-not-at-top
  os.makedirs(out_dir, exist_ok=True)
  config, problem, trainer, state, _ = evaluate.load_run(workdir, data_dir)
  c = config.train.input_frames
  results = evaluate.rollout_split(trainer, state, problem,
                                   data.split_path(data_dir, split), c,
                                   max_trajectories)
  paths = {"predicted": os.path.join(out_dir, "predicted.h5"),
           "truth": os.path.join(out_dir, "truth.h5")}
  stats = {k: v for k, v in mpm_io.read_header(
      data.split_path(data_dir, split)).items() if k.endswith(("_mean",
                                                               "_std"))}
  predicted = [dataclasses.replace(
      r["trajectory"], positions=np.concatenate(
          [r["trajectory"].positions[:c], r["predicted"]]).astype(np.float32))
               for r in results]
  mpm_io.write_trajectories(paths["predicted"], predicted, stats=stats)
  mpm_io.write_trajectories(paths["truth"], [r["trajectory"] for r in results],
                            stats=stats)
  return paths


def demo_scene(num_frames: int = 600) -> mpm.Scene:
  """The paper's Figure 2 set-up: 900 particles, one semicircle."""
  return mpm.Scene.from_dict({
      "name": "figure2",
      "obstacles": [{"shape": "semicircle", "x": 0.9, "radius": 0.04}],
      "granular": {"box": list(mpm.scene.Granular.box), "spacing": 0.005,
                   "num_particles": 900},
      "num_frames": num_frames,
  })


def demo(out_dir: str, num_frames: int = 600) -> dict[str, str]:
  """Simulates the demo scene, renders it; returns the paths written."""
  os.makedirs(out_dir, exist_ok=True)
  scene = demo_scene(num_frames)
  paths = {"scene": os.path.join(out_dir, "scene.json"),
           "trajectory": os.path.join(out_dir, "trajectory.h5")}
  with open(paths["scene"], "w") as f:
    f.write(scene.to_json(indent=2))
  result = simulate_to_file(scene, paths["trajectory"])
  paths["animation"], paths["frames"] = render_file(paths["trajectory"],
                                                    out_dir)
  print(f"MPM: {result.positions.shape[0]} frames of "
        f"{result.positions.shape[1]} particles in {result.wall_time_s:.2f} s "
        f"({result.n_substeps} substeps/frame; compiling took "
        f"{result.compile_time_s:.2f} s)")
  return paths
