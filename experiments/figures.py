"""Every picture of the project (matplotlib lives here and nowhere else).

Evaluation figures: training curves (the paper's Figs. 3-4), test error by
checkpoint (Fig. 5), error-against-time breakdowns (Figs. 6-9), and the flow
checks a positional MSE misses (sand inside solids or outside the domain,
front error, the constraint's work) per step.
"""

import os
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
# pylint: disable=g-import-not-at-top,wrong-import-position
import matplotlib.pyplot as plt
import numpy as np


def _save(fig, path: str):
  fig.tight_layout()
  tmp = f"{path}.tmp-{os.getpid()}.png"
  fig.savefig(tmp, dpi=100)
  plt.close(fig)
  os.replace(tmp, path)


def training_curves(log: Sequence[dict], out_dir: str):
  """fig3_training_loss.png and fig4_training_time.png from metrics.csv
  rows (step, loss, wall_time_s)."""
  steps = [int(r["step"]) for r in log]
  for name, key, label in (("fig3_training_loss", "loss", "training loss"),
                           ("fig4_training_time", "wall_time_s",
                            "training time (h)")):
    values = [float(r[key]) / (3600 if key == "wall_time_s" else 1)
              for r in log]
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(steps, values)
    ax.set_xlabel("training step")
    ax.set_ylabel(label)
    if key == "loss":
      ax.set_yscale("log")
    _save(fig, os.path.join(out_dir, f"{name}.png"))


_TITLES = {"fig6_obstacles": "obstacle count", "fig7_particles":
           "particle count", "fig8_shape": "obstacle shape",
           "fig9_position": "rectangle position x (m)"}


def breakdown_curves(curves: dict[str, dict[str, np.ndarray]],
                     times: np.ndarray, out_dir: str):
  """Figs. 6-9: positional MSE against time (s) [T] per label."""
  for name, groups in curves.items():
    if not groups:
      continue
    fig, ax = plt.subplots(figsize=(5, 3.5))
    for label, curve in groups.items():
      ax.plot(times, curve, label=label)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("positional MSE (m$^2$)")
    ax.set_yscale("log")
    ax.set_title(_TITLES.get(name, name))
    ax.legend()
    _save(fig, os.path.join(out_dir, f"{name}.png"))


def checkpoint_errors(errors: dict[int, float], path: str):
  """Fig. 5: test MSE (m^2) of each checkpoint step."""
  fig, ax = plt.subplots(figsize=(5, 3.5))
  ax.plot(list(errors), list(errors.values()), "o-")
  ax.set_xlabel("training step")
  ax.set_ylabel("test positional MSE (m$^2$)")
  ax.set_yscale("log")
  _save(fig, path)


def flow_checks(results: Sequence[dict], frame_dt: float, path: str):
  """Per step, mean over trajectories of each test group: sand inside solids
  (with and without the constraint), outside the domain, the front error
  and the fraction the constraint pushed. ``results`` from
  ``experiments.evaluation.rollout_split``."""
  groups: dict[str, list] = {}
  for r in results:
    groups.setdefault(r["group"], []).append(r)
  panels = [("inside_solids", "sand inside solids (constrained)", 100),
            ("free_inside_solids", "sand inside solids (no constraint)", 100),
            ("outside_domain", "sand outside the domain (constrained)", 100),
            ("runout_error", "front error (m)", 1),
            ("pushed_fraction", "sand pushed out per step", 100),
            ("mse", "positional MSE (m$^2$)", 1)]
  fig, axes = plt.subplots(2, 3, figsize=(14, 7))
  for ax, (key, title, scale) in zip(axes.flat, panels):
    for name, members in sorted(groups.items()):
      if key not in members[0]:
        continue
      curve = np.mean([m[key] for m in members], 0) * scale
      ax.plot(members[0]["frames"] * frame_dt, curve, label=name)
    ax.set_title(title)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("% of the sand" if scale == 100 else "")
    if key == "mse":
      ax.set_yscale("log")
  axes.flat[0].legend(fontsize=7)
  _save(fig, path)
