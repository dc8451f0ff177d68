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
from experiments import figures
from gnsjax import data
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
  anim = figures.animate(panels, t.scene, t.boundary_positions,
                         t.boundary_type,
                         os.path.join(out_dir, f"animation.{fmt}"))
  grid = figures.frame_grid(panels, t.scene, t.boundary_positions,
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
  config.checkpoint.every_steps = 100
  config.checkpoint.named_steps = ()
  config.eval.every_steps = 0
  return config


def _ship_checkpoint(source: str, workdir: str) -> int:
  """Copies a shipped checkpoint into ``workdir``; returns its step."""
  import shutil  # pylint: disable=g-import-not-at-top
  steps = sorted(int(d) for d in os.listdir(os.path.join(source, "checkpoints"))
                 if d.isdigit())
  target = os.path.join(workdir, "checkpoints", str(steps[-1]))
  if not os.path.exists(target):
    shutil.copytree(os.path.join(source, "checkpoints", str(steps[-1])),
                    target)
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
  from gnsjax import evaluate as evaluate_lib  # pylint: disable=g-import-not-at-top
  from gnsjax import metrics  # pylint: disable=g-import-not-at-top
  from gnsjax import rollout as rollout_lib  # pylint: disable=g-import-not-at-top
  from gnsjax import train  # pylint: disable=g-import-not-at-top
  from mpm import dataset  # pylint: disable=g-import-not-at-top

  os.makedirs(out_dir, exist_ok=True)
  data_dir = os.path.join(out_dir, "data")
  workdir = os.path.join(out_dir, "run")
  os.makedirs(workdir, exist_ok=True)
  start = 0
  if pretrained and os.path.isdir(os.path.join(pretrained, "checkpoints")):
    start = _ship_checkpoint(pretrained, workdir)
  config = demo_config(num_train, num_test, start + finetune_steps,
                       num_frames)
  spec = dataset.DatasetSpec(**config.dataset.to_dict())
  with tqdm.tqdm(total=spec.num_train + spec.num_test, unit="traj",
                 desc="dataset") as bar:
    dataset.generate(spec, data_dir, workers=workers,
                     progress=lambda done, *_: bar.update(done - bar.n))
  train.train_and_evaluate(config, data_dir, workdir)

  _, problem, trainer, state, step = evaluate_lib.load_run(workdir, data_dir)
  c = config.train.input_frames
  t = next(t for t in data.trajectories(data.split_path(data_dir, "test"))
           if dataset.group_of(t.scene.name) == "triangle")
  predicted = rollout_lib.rollout_trajectory(
      trainer.model, state.params, t, problem, len(t.positions) - c, c)
  truth = t.positions[c:]
  v = t.positions[c - 1] - t.positions[c - 2]
  constant = t.positions[c - 1][None] + v[None] * np.arange(
      1, len(truth) + 1)[:, None, None]
  mse = metrics.positional_mse(predicted, truth)
  result = {
      "scene": t.scene.name, "model_step": step, "fine_tuned_from": start,
      "particles": int(t.positions.shape[1]), "steps": len(truth),
      "gns_mean_mse_m2": float(np.mean(mse)),
      "gns_final_mse_m2": float(mse[-1]),
      "constant_velocity_mean_mse_m2": float(np.mean(
          metrics.positional_mse(constant, truth))),
      "gns_final_runout_error_m": float(
          metrics.runout_error(predicted, truth)[-1]),
      "gns_deposit_error_m": metrics.deposit_error(
          predicted[-1], truth[-1], 2 * t.scene.granular.spacing),
  }
  paths = {"data": data_dir, "run": workdir,
           "metrics": os.path.join(out_dir, "metrics.json"),
           "truth": os.path.join(out_dir, "truth.h5"),
           "predicted": os.path.join(out_dir, "predicted.h5")}
  mpm_io.write_json(paths["metrics"], result)
  stats = {k: v for k, v in mpm_io.read_header(
      data.split_path(data_dir, "test")).items() if k.endswith(("_mean",
                                                                "_std"))}
  mpm_io.write_trajectories(paths["truth"], [t], stats=stats)
  mpm_io.write_trajectories(paths["predicted"], [dataclasses.replace(
      t, positions=np.concatenate([t.positions[:c], predicted]).astype(
          np.float32))], stats=stats)
  paths["animation"], paths["frames"] = render_file(
      paths["truth"], out_dir, compare_path=paths["predicted"])
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


def inverse_design(out_dir: str, *, scene_path: str | None = None,
                   shape: str = "semicircle", size: Sequence[float] = (0.04,),
                   x0: float = 1.0, num_frames: int = 600,
                   simulator: str = "gns", objective: str = "passed_fraction",
                   x_protect: float = 0.4, target_x: float = 0.6,
                   temperature: float | None = None,
                   workdir: str | None = PRETRAINED, steps: int = 8,
                   learning_rate: float = 0.05, sweep_points: int = 9,
                   optimise_size: bool = False) -> dict:
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
      optimise_size=optimise_size, log=lambda line: tqdm.tqdm.write(line))
  figures.objective_vs_x(result.sweep, result.history, obj.name, simulator,
                         os.path.join(out_dir, "objective_vs_x.png"))
  return result.summary
