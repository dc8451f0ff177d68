"""The jobs behind the entry points, as plain functions (no flags here).

Each ``experiments/<name>.py`` parses flags and calls one function of this
module, so that jobs compose (the demo runs several) and tests call them
directly.
"""

import os
from typing import Sequence

import tqdm

import mpm
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


def render_file(traj_path: str, out_dir: str, index: int = 0,
                frames: Sequence[int] = (1, 80, 120, 180),
                fmt: str = "gif") -> tuple[str, str]:
  """Writes ``animation.<fmt>`` and ``frames.png`` for one trajectory."""
  trajectories = list(mpm_io.read_trajectories(traj_path))
  if not 0 <= index < len(trajectories):
    raise ValueError(f"index={index}: the file holds {len(trajectories)} "
                     f"trajectories; allowed: 0..{len(trajectories) - 1}")
  t = trajectories[index]
  os.makedirs(out_dir, exist_ok=True)
  panels = [(f"MPM: {t.scene.name}", t.positions)]
  frames = [f for f in frames if f < len(t.positions)]
  anim = render.animate(panels, t.scene, t.boundary_positions, t.boundary_type,
                        os.path.join(out_dir, f"animation.{fmt}"))
  grid = render.frame_grid(panels, t.scene, t.boundary_positions,
                           t.boundary_type, frames,
                           os.path.join(out_dir, "frames.png"))
  return anim, grid


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
