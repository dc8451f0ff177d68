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
  from experiments import evaluation  # pylint: disable=g-import-not-at-top
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


# The training recipe's parts, added one at a time (docs/gns.md): each entry
# changes the config of the entry before it. "previous" is the recipe of the
# first small model (with the SDF node features every model now has).
ABLATION = (
    ("previous", {"model.boundary_particles": True, "train.frame_stride": 1,
                  "train.noise_std": 1e-4,
                  "train.noise_velocity_fraction": 0.0,
                  "train.fold_noise": False, "train.motion_weighting": 0.0,
                  "train.pushforward_steps": 0}),
    ("stride3", {"train.frame_stride": 3}),
    ("sdf_only", {"model.boundary_particles": False}),
    ("noise_folded", {"train.noise_velocity_fraction": 0.1,
                      "train.fold_noise": True}),
    ("motion_weighted", {"train.motion_weighting": 0.5}),
    ("pushforward", {"train.pushforward_steps": 2,
                     "train.pushforward_probability": 0.5}),
)


def ablation(data_dir: str, out_dir: str, *, minutes: float = 8.0,
             variants: Sequence[str] | None = None,
             max_trajectories: int | None = 7,
             unconstrained: bool = False) -> list[dict]:
  """Trains each cumulative variant of ``ABLATION`` for the same wall time
  and scores whole rollouts of the test split (``max_trajectories``: the
  first ones; the test split cycles its groups, so 7 is one per group).

  The rollouts keep sand out of solids; how much each model leans on that
  is the fraction the constraint pushes per step. ``unconstrained`` also
  rolls out without it (slow for weak models: sand that leaves the domain
  piles up at the neighbour search's clip boundary and the graph densifies).

  Writes ``ablation.json`` and ``ablation.md`` in ``out_dir``; each
  variant's run lives in ``out_dir/<name>`` (a rerun resumes or reuses it).
  """
  from experiments import evaluation  # pylint: disable=g-import-not-at-top
  from experiments.configs import small  # pylint: disable=g-import-not-at-top
  from gnsjax import train  # pylint: disable=g-import-not-at-top
  import jax  # pylint: disable=g-import-not-at-top
  known = [name for name, _ in ABLATION]
  unknown = set(variants or ()) - set(known)
  if unknown:
    raise ValueError(f"variants {sorted(unknown)}; allowed: {known}")
  os.makedirs(out_dir, exist_ok=True)
  config = small.get_config()
  config.train.num_steps = 10**7            # the time budget stops it
  config.train.max_wall_time_s = minutes * 60
  config.eval.every_steps = 0
  config.checkpoint.named_steps = ()
  rows = []
  test_path = data.split_path(data_dir, "test")
  for name, changes in ABLATION:
    for key, value in changes.items():
      section, field = key.split(".")
      config[section][field] = value
    if variants and name not in variants:
      continue
    workdir = os.path.join(out_dir, name)
    # No program of one variant serves the next, and XLA:CPU keeps every
    # compiled program mapped until it is freed: six trainings in one
    # process ran out of memory maps and crashed.
    jax.clear_caches()
    train.train_and_evaluate(config, data_dir, workdir)
    run = train.load_run(workdir)
    results = evaluation.rollout_split(run, test_path, max_trajectories,
                                       unconstrained)
    summary = evaluation.group_summary(
        [evaluation.per_trajectory_row(r) for r in results])[0]
    log = evaluation.read_csv(os.path.join(workdir, "metrics.csv"))
    rows.append({"variant": name, "changes": changes, "steps": run.step,
                 "train_minutes": float(log[-1]["wall_time_s"]) / 60
                 if log else None, **summary})
    mpm_io.write_json(os.path.join(out_dir, "ablation.json"), rows)
  mpm_io.write_text(os.path.join(out_dir, "ablation.md"),
                    ablation_table(rows))
  return rows


def ablation_table(rows: Sequence[dict]) -> str:
  """The Markdown table of an ablation's rows."""
  lines = ["| variant | steps | mean MSE (m^2) | const. vel. | median front "
           "error | median deposit error (m) | inside (max) | free: inside "
           "(max) | outside (max) | pushed/step |",
           "|---|---|---|---|---|---|---|---|---|---|"]
  for r in rows:
    lines.append(
        f"| {r['variant']} | {r['steps']} | {r['mean_mse']:.2e} | "
        f"{r['mean_mse_constant_velocity']:.2e} | "
        f"{r['median_front_error_relative']:.1%} | "
        f"{r['median_deposit_error']:.4f} | {r['max_inside_solids']:.1%} | "
        f"{r.get('free_max_inside_solids', float('nan')):.1%} | "
        f"{r['max_outside_domain']:.1%} | {r['mean_pushed_fraction']:.2%} |")
  return "\n".join(lines) + "\n"
