"""The training recipe's ablation (``python -m experiments.ablation``): each
part of the recipe added in turn, every variant trained for the same wall
time, whole test rollouts scored (docs/gns.md).

``ABLATION`` lists the parts: each entry changes the config of the entry
before it, from the recipe of the first small model ("previous") to the
recipe of ``experiments/configs/small.py``. ``run`` trains the variants
(each in ``out_dir/<name>``, which a rerun resumes or reuses) and scores
them with the evaluation's rollouts (``experiments.studies.evaluation``).
"""

import dataclasses
import os
from typing import Any

import jax

from experiments.configs import small
from experiments.studies import evaluation
from experiments.studies import settings
from gnsjax import data
from gnsjax import run as run_lib
from gnsjax import train
from mpm import io as mpm_io

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
    ("rest_noise", {"train.noise_velocity_fraction": 0.25}),
    ("pushforward", {"train.pushforward_steps": 2,
                     "train.pushforward_probability": 0.5}),
)
VARIANTS = tuple(name for name, _ in ABLATION)


@dataclasses.dataclass(frozen=True)
class Settings(settings.Base):
  """Which variants to train on which data, for how long, scored how."""
  data: str = settings.field(None, "Dataset directory (small config).")
  minutes: float = settings.field(
      8.0, "Training wall time per variant (minutes).", lower=0,
      strict=True)
  variants: tuple[str, ...] | None = settings.field(
      None, "Variants to run (default: all).", choices=VARIANTS)
  max_trajectories: int | None = settings.field(
      7, "Test trajectories per variant (the first ones; the test split "
      "cycles its 7 groups, so 7 is one per group).", lower=1)
  unconstrained: bool = settings.field(
      False, "Also roll out without the solid constraint (slow for weak "
      "models: sand that leaves the domain piles up at the neighbour "
      "search's clip boundary and the graph densifies).")


def run(s: Settings, out_dir: str) -> dict[str, Any]:
  """Trains each cumulative variant of ``ABLATION`` (those of
  ``s.variants``) for ``s.minutes`` and scores whole rollouts of the test
  split.

  The rollouts keep sand out of solids; how much each model leans on that
  is the fraction the constraint pushes per step (``mean_pushed_fraction``).
  Writes ``ablation.json`` (the rows, after each variant) and
  ``ablation.md`` (``report``) in ``out_dir``; each variant's run lives in
  ``out_dir/<name>``.

  Returns:
    {"rows": one per variant run: its name, changes, steps, training
    minutes and the evaluation's summary over all its test trajectories
    (``evaluation.group_summary``)}.
  """
  os.makedirs(out_dir, exist_ok=True)
  config = small.get_config()
  config.train.num_steps = 10**7            # the time budget stops it
  config.train.max_wall_time_s = s.minutes * 60
  config.eval.every_steps = 0
  config.checkpoint.named_steps = ()
  rows = []
  test_path = data.split_path(s.data, "test")
  for name, changes in ABLATION:
    for key, value in changes.items():
      section, field = key.split(".")
      config[section][field] = value
    if s.variants is not None and name not in s.variants:
      continue
    workdir = os.path.join(out_dir, name)
    # No program of one variant serves the next, and XLA:CPU keeps every
    # compiled program mapped until it is freed: six trainings in one
    # process ran out of memory maps and crashed.
    jax.clear_caches()
    train.train_and_evaluate(config, s.data, workdir)
    trained = run_lib.load_run(workdir)
    results = evaluation.rollout_split(trained, test_path,
                                       s.max_trajectories, s.unconstrained)
    summary = evaluation.group_summary(
        [evaluation.per_trajectory_row(r) for r in results])[0]
    log = evaluation.read_csv(os.path.join(workdir, "metrics.csv"))
    rows.append({"variant": name, "changes": changes, "steps": trained.step,
                 "train_minutes": float(log[-1]["wall_time_s"]) / 60
                 if log else None, **summary})
    mpm_io.write_json(os.path.join(out_dir, "ablation.json"), rows)
  summary = {"rows": rows}
  mpm_io.write_text(os.path.join(out_dir, "ablation.md"), report(summary))
  return summary


def report(summary: dict[str, Any]) -> str:
  """The Markdown table of an ablation's rows."""
  lines = ["| variant | steps | mean MSE (m^2) | const. vel. | median front "
           "error | median deposit error (m) | inside (max) | free: inside "
           "(max) | outside (max) | pushed/step |",
           "|---|---|---|---|---|---|---|---|---|---|"]
  for r in summary["rows"]:
    lines.append(
        f"| {r['variant']} | {r['steps']} | {r['mean_mse']:.2e} | "
        f"{r['mean_mse_constant_velocity']:.2e} | "
        f"{r['median_front_error_relative']:.1%} | "
        f"{r['median_deposit_error']:.4f} | {r['max_inside_solids']:.1%} | "
        f"{r.get('free_max_inside_solids', float('nan')):.1%} | "
        f"{r['max_outside_domain']:.1%} | {r['mean_pushed_fraction']:.2%} |")
  return "\n".join(lines) + "\n"
