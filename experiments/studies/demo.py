"""The end-to-end demo (``python -m experiments.demo``, ``make demo``): data,
model, rollout of an unseen scene, pictures.

1. Generates a small dataset (the small config's physics, few scenes).
2. Fine-tunes the shipped pretrained small model (``settings.PRETRAINED``)
   on it for ``finetune_steps`` steps (or, without one, trains from
   scratch).
3. Rolls the model out on the test scene with the triangle obstacle, a
   shape never seen in training, and measures it against the MPM and a
   constant-velocity baseline (``experiments.studies.evaluation``).
4. Writes the metrics and an MPM | GNS animation and frame grid.
"""

import dataclasses
import hashlib
import os
import shutil
from typing import Any

import numpy as np
import tqdm

from experiments import file_jobs
from experiments.configs import small
from experiments.studies import evaluation
from experiments.studies import settings
from gnsjax import data
from gnsjax import rollout as rollout_lib
from gnsjax import run as run_lib
from gnsjax import train
from mpm import budget
from mpm import dataset
from mpm import io as mpm_io

# The small model's first prediction needs its input frames at its stride.
MIN_FRAMES = (small.get_config().train.input_frames *
              small.get_config().train.frame_stride + 1)
# The scene rolled out: the test plan's first triangle (dataset.TEST_GROUPS
# cycle), so the test split holds the scenes up to it.
_SHOWN_GROUP = "triangle"
_NUM_TEST = [g[0] for g in dataset.TEST_GROUPS].index(_SHOWN_GROUP) + 1

# In a demo's work directory: which shipped checkpoint it was started from.
SHIPPED_RECORD = "shipped_from.json"


@dataclasses.dataclass(frozen=True)
class Settings(settings.Base):
  """How much data and training the demo makes."""
  finetune_steps: int = settings.field(200, "Training steps.", lower=1)
  num_train: int = settings.field(4, "Training scenes to simulate.",
                                  lower=1)
  num_frames: int = settings.field(600, "Frames per scene.",
                                   lower=MIN_FRAMES)
  pretrained: bool = settings.field(
      True, "Start from a trained model (--model); no: train from scratch.")
  model: str = settings.field(
      "", "Trained model to start from: a run or averaged-run directory "
      "(default: the shipped small model).")
  workers: int = settings.field(2, "Processes simulating the dataset.",
                                lower=1)

  def simulations(self) -> list[budget.Planned]:
    """The demo's dataset, --workers scenes at once."""
    config = demo_config(self.num_train, _NUM_TEST, self.finetune_steps,
                         self.num_frames)
    plan = dataset.plan(dataset.DatasetSpec(**config.dataset.to_dict()))
    names = {"num_frames": "--num_frames", "scenes": "--workers",
             "spacing": None, "dx": None}
    return [budget.Planned(p.scene, at_once=min(self.workers, len(plan)),
                           names=names) for p in plan]


# How the shipped model's training windows were made (noise, clean
# windows, pushforward): its fine-tuning keeps them. Fine-tuned another
# way, even for 200 steps, it drifts from what it learned (a fine-tuning
# without its pushforward raised its error on the demo's scene 2.7-fold:
# docs/results.md, the demo).
RECIPE_KEYS = ("noise_std", "noise_velocity_fraction", "fold_noise",
               "motion_weighting", "target_outside_solids", "clean_fraction",
               "clean_resting_only", "clean_weight", "clean_scale_min",
               "pushforward_steps", "pushforward_probability",
               "pushforward_constrained", "rest_pushforward_steps",
               "rest_pushforward_probability", "rest_pushforward_speed",
               "rest_pushforward_stay", "unroll_steps", "unroll_probability")


# The model options a shipped model may have beyond the small config's: a
# fine-tuning of it must have the same.
MODEL_KEYS = ("smooth_cutoff", "velocity_gate", "solid_range")


def demo_config(num_train: int, num_test: int, steps: int,
                num_frames: int = 600, recipe: dict | None = None,
                model: dict | None = None):
  """configs/small.py with a demo-sized dataset and a short training, with
  the ``RECIPE_KEYS`` that ``recipe`` (a shipped model's ``config.train``)
  holds, and the ``MODEL_KEYS`` that ``model`` (its ``config.model``)
  holds."""
  config = small.get_config()
  for keys, section, given in ((RECIPE_KEYS, "train", recipe),
                               (MODEL_KEYS, "model", model)):
    for key in keys:
      if given is not None and key in given:
        config[section][key] = given[key]
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


def _identity(source: str, step: int) -> dict[str, Any]:
  """What tells a model's checkpoint from another's: its step and the hash
  of its ``provenance.json`` (a shipped model) or, without one, its
  directory and the hash of the config its checkpoint holds (a run or an
  averaged run)."""
  provenance = os.path.join(source, "provenance.json")
  if os.path.exists(provenance):
    with open(provenance, "rb") as f:
      return {"step": step,
              "provenance_sha256": hashlib.sha256(f.read()).hexdigest()}
  config = run_lib.load_config(source, step).to_json(sort_keys=True)
  return {"step": step, "source": os.path.abspath(source),
          "config_sha256": hashlib.sha256(config.encode()).hexdigest()}


def ship_checkpoint(source: str, workdir: str) -> int:
  """Copies the last checkpoint of a trained model (the shipped one, a run
  or an averaged run) into ``workdir``; returns its step.

  A work directory started from another checkpoint (an older model, before
  an update) would resume its own run and silently show the old model, so
  it is refused.

  Raises:
    settings.InputError: when ``source`` holds no checkpoint, or
      ``workdir`` holds checkpoints not started from this one (it names what
      to delete).
  """
  held_by_source = os.path.join(source, "checkpoints")
  steps = sorted(int(d) for d in (os.listdir(held_by_source)
                                  if os.path.isdir(held_by_source) else ())
                 if d.isdigit())
  if not steps:
    raise settings.InputError(
        f"--model={source}: no trained model there; allowed: a run or "
        "averaged-run directory with checkpoints/<step>")
  shipped = _identity(source, steps[-1])
  record = os.path.join(workdir, SHIPPED_RECORD)
  held = os.path.join(workdir, "checkpoints")
  if os.path.isdir(held) and os.listdir(held):
    previous = mpm_io.read_json(record) if os.path.exists(record) else None
    if previous != shipped:
      raise settings.InputError(
          f"{workdir} holds a run started from another model (or from "
          f"none); delete {workdir} (or choose another --out) to start "
          f"from {source}")
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


def run(s: Settings, out_dir: str) -> dict[str, Any]:
  """Runs the demo in ``out_dir``: ``data/`` (the dataset), ``run/`` (the
  model), ``metrics.json``, ``truth.h5`` and ``predicted.h5`` (the input
  frames at the learned stride, then the MPM's and the model's frames),
  ``animation.gif`` and ``frames.png`` (MPM | GNS).

  Returns:
    {"metrics": what ``metrics.json`` holds (errors in m and m^2, speeds
    in m/s), "paths": name -> path of each output}.
  """
  os.makedirs(out_dir, exist_ok=True)
  data_dir = os.path.join(out_dir, "data")
  workdir = os.path.join(out_dir, "run")
  os.makedirs(workdir, exist_ok=True)
  start, recipe, shipped_model = 0, None, None
  model = s.model or settings.PRETRAINED
  # The shipped model may be missing (a checkout without it): the demo then
  # trains from scratch. A model named by --model must be there.
  if s.pretrained and (s.model or os.path.isdir(
      os.path.join(model, "checkpoints"))):
    start = ship_checkpoint(model, workdir)
    shipped = run_lib.load_config(model)
    recipe, shipped_model = shipped.train.to_dict(), shipped.model.to_dict()
  config = demo_config(s.num_train, _NUM_TEST, start + s.finetune_steps,
                       s.num_frames, recipe, shipped_model)
  spec = dataset.DatasetSpec(**config.dataset.to_dict())
  with tqdm.tqdm(total=spec.num_train + spec.num_test, unit="traj",
                 desc="dataset") as bar:
    dataset.generate(spec, data_dir, workers=s.workers,
                     progress=lambda done, *_: bar.update(done - bar.n))
  train.train_and_evaluate(config, data_dir, workdir)

  trained = run_lib.load_run(workdir)
  c, k = trained.problem.input_frames, trained.problem.frame_stride
  t = next(t for t in data.trajectories(data.split_path(data_dir, "test"))
           if dataset.group_of(t.scene.name) == _SHOWN_GROUP)
  frames = rollout_lib.predicted_frame_indices(len(t.positions), c, k)
  with tqdm.tqdm(total=1, unit="rollout", desc="GNS rollout") as bar:
    out = rollout_lib.rollout_trajectory(trained.model, trained.params, t,
                                         trained.problem)
    bar.update(1)
  scores = evaluation.score(t, out, frames, trained.problem)
  row = evaluation.per_trajectory_row({
      "index": 0, "name": t.scene.name, **evaluation.describe(t.scene),
      **scores})
  metrics = {
      "scene": t.scene.name, "model_step": trained.step,
      "started_from": model if start else "scratch",
      "fine_tuned_from": start,
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
      "gns_kinetic_energy_ratio": row["kinetic_energy_ratio"],
      "mpm_max_inside_solids": row["mpm_max_inside_solids"],
      "gns_mean_pushed_fraction": row["mean_pushed_fraction"],
  }
  paths = {"data": data_dir, "run": workdir,
           "metrics": os.path.join(out_dir, "metrics.json"),
           "truth": os.path.join(out_dir, "truth.h5"),
           "predicted": os.path.join(out_dir, "predicted.h5")}
  mpm_io.write_json(paths["metrics"], metrics)
  inputs = rollout_lib.input_frame_indices(c, k)
  mpm_io.write_trajectories(paths["truth"], [file_jobs.with_frames(
      t, t.positions[np.concatenate([inputs, frames])], k)])
  mpm_io.write_trajectories(paths["predicted"], [file_jobs.with_frames(
      t, np.concatenate([t.positions[inputs], out.positions]), k)])
  shown = np.linspace(1, len(inputs) + len(frames) - 1, 5).astype(int)
  paths["animation"], paths["frames"] = file_jobs.render_file(
      paths["truth"], out_dir, frames=tuple(shown),
      compare_path=paths["predicted"])
  return {"metrics": metrics, "paths": paths}


def report(summary: dict[str, Any]) -> str:
  """The demo's metrics and files (Markdown)."""
  lines = ["# Demo", "", "| metric | value |", "|---|---|"]
  for key, value in summary["metrics"].items():
    shown = f"{value:.4g}" if isinstance(value, float) else value
    lines.append(f"| {key} | {shown} |")
  lines += ["", "| output | path |", "|---|---|"]
  lines += [f"| {name} | `{path}` |"
            for name, path in summary["paths"].items()]
  return "\n".join(lines) + "\n"
