"""The paper's evaluation of a trained run on a dataset (section III).

``evaluate(workdir, data_dir, out_dir)`` writes PNG figures, every number as
CSV/JSON, and a Markdown report:

- Fig. 3: training loss against steps; Fig. 4: training time against steps
  (from ``metrics.csv``);
- Fig. 5: test error (positional MSE over all test trajectories, particles and
  steps) of the named checkpoints (the paper's V1-V4) and the latest;
- Figs. 6-9: positional MSE against time by obstacle count, particle count,
  obstacle shape (the triangle was never seen in training) and rectangle
  position;
- runout and deposit-profile errors per trajectory;
- Table 2: MPM and GNS wall time per simulation, side by side in this run on
  this hardware (compilation excluded, synchronised, medians of repeats), each
  beside its accuracy.
"""

import csv
import json
import os
import time
from typing import Any, Sequence

import jax
import matplotlib

matplotlib.use("Agg")
# pylint: disable=g-import-not-at-top,wrong-import-position
import matplotlib.pyplot as plt
import numpy as np

import mpm
from gnsjax import batching
from gnsjax import checkpoint
from gnsjax import data
from gnsjax import metrics
from gnsjax import rollout as rollout_lib
from gnsjax import simulator
from gnsjax import train
from mpm import dataset as dataset_lib
from mpm import io as mpm_io


def load_run(workdir: str, data_dir: str | None = None,
             step: int | None = None, scene: mpm.Scene | None = None):
  """(config, problem, trainer, state, step) of a run's checkpoint.

  Every checkpoint stores its config and statistics, so a work directory (or
  a shipped model such as ``experiments/pretrained/small``) restores on its
  own. The domain and connectivity radius come from the dataset of
  ``data_dir`` or, without one, from ``scene``'s domain and the config.
  """
  import ml_collections  # pylint: disable=g-import-not-at-top
  mngr = checkpoint.manager(workdir, every_steps=1)
  step = mngr.latest_step() if step is None else step
  if step is None:
    raise FileNotFoundError(f"{workdir}: no checkpoint to evaluate")
  config = ml_collections.ConfigDict(checkpoint.read_config(mngr, step))
  stats = checkpoint.read_stats(mngr, step)
  if data_dir is not None:
    problem = train.load_problem(data_dir, config, stats)
  elif scene is not None:
    problem = train.make_problem(
        config, stats, [[0.0, scene.domain.width], [0.0, scene.domain.height]],
        config.dataset.connectivity_radius)
  else:
    raise ValueError("load_run: give data_dir or scene (for the domain)")
  trainer = train.Trainer(config, problem)
  state, _, _ = checkpoint.restore(mngr, trainer.init_state(0), step)
  mngr.close()
  return config, problem, trainer, state, step


def checkpoint_steps(workdir: str) -> list[int]:
  path = os.path.join(workdir, "checkpoints")
  if not os.path.isdir(path):
    return []
  return sorted(int(d) for d in os.listdir(path) if d.isdigit())


def describe(scene: mpm.Scene) -> dict:
  """The breakdown labels of a test scene."""
  shapes = [o.shape for o in scene.obstacles]
  return {
      "group": dataset_lib.group_of(scene.name),
      "obstacles": len(shapes),
      "particles": scene.granular.num_particles,
      "shape": shapes[0] if len(shapes) == 1 else "",
      "x": scene.obstacles[0].x if len(shapes) == 1 else None,
  }


def rollout_split(trainer, state, problem, path: str, input_frames: int,
                  max_trajectories: int | None = None) -> list[dict]:
  """Rolls out every trajectory of a split from its first frames."""
  results = []
  predictor = simulator.ModelPredictor(trainer.model)
  for i, t in enumerate(data.trajectories(path)):
    if max_trajectories is not None and i >= max_trajectories:
      break
    window, types, moving = rollout_lib.trajectory_nodes(t, input_frames)
    steps = len(t.positions) - input_frames
    pred = rollout_lib.rollout(predictor, state.params, window, types, moving,
                               steps, problem.context, problem.spec)
    pred = pred[:, :t.positions.shape[1]]
    truth = t.positions[input_frames:]
    results.append({
        "index": i, "name": t.scene.name, **describe(t.scene),
        "trajectory": t, "predicted": pred, "truth": truth,
        "mse": metrics.positional_mse(pred, truth),
        "runout_error": metrics.runout_error(pred, truth),
        "deposit_error": metrics.deposit_error(
            pred[-1], truth[-1], 2 * t.scene.granular.spacing),
    })
  return results


BREAKDOWNS = {
    "fig6_obstacles": ("obstacles", lambda r: True),
    "fig7_particles": ("particles", lambda r: True),
    "fig8_shape": ("shape", lambda r: r["obstacles"] == 1),
    "fig9_position": ("x", lambda r: r["obstacles"] == 1 and
                      r["group"].startswith("rectangle")),
}


def breakdown(results: Sequence[dict]) -> dict[str, dict[str, np.ndarray]]:
  """Mean MSE curve [T] per label, for each of the paper's Figs. 6-9."""
  out = {}
  for fig, (key, keep) in BREAKDOWNS.items():
    groups: dict[str, list] = {}
    for r in results:
      if keep(r):
        groups.setdefault(str(r[key]), []).append(r["mse"])
    out[fig] = {label: np.mean(np.stack(curves), 0)
                for label, curves in sorted(groups.items())}
  return out


def _median_time(fn, repeats: int) -> float:
  times = []
  for _ in range(repeats):
    start = time.perf_counter()
    fn()
    times.append(time.perf_counter() - start)
  return float(np.median(times))


def table2(trainer, state, problem, results: Sequence[dict], input_frames: int,
           repeats: int = 3) -> list[dict]:
  """MPM vs GNS seconds per simulation, one scene per test group.

  The MPM time is ``mpm.simulate``'s simulation time (compilation excluded,
  each chunk synchronised); the GNS time is a full rollout after a warm-up
  rollout (compilation excluded), synchronised by fetching the result.
  """
  rows = []
  predictor = simulator.ModelPredictor(trainer.model)
  seen = set()
  for r in results:
    if r["group"] in seen:
      continue
    seen.add(r["group"])
    t = r["trajectory"]
    mpm.simulate(t.scene)  # compile
    mpm_times = [mpm.simulate(t.scene).wall_time_s for _ in range(repeats)]
    window, types, moving = rollout_lib.trajectory_nodes(t, input_frames)
    steps = len(t.positions) - input_frames
    run = lambda: rollout_lib.rollout(predictor, state.params, window, types,
                                      moving, steps, problem.context,
                                      problem.spec)
    run()  # compile
    gns = _median_time(run, repeats)
    rows.append({
        "group": r["group"], "particles": r["particles"],
        "obstacles": r["obstacles"], "frames": len(t.positions),
        "mpm_s": float(np.median(mpm_times)), "gns_s": gns,
        "speedup": float(np.median(mpm_times)) / gns,
        "gns_mse": float(np.mean(r["mse"])),
    })
  return rows


def _plot_curves(curves: dict[str, np.ndarray], frame_dt: float, title: str,
                 path: str):
  fig, ax = plt.subplots(figsize=(5, 3.5))
  for label, curve in curves.items():
    ax.plot(np.arange(1, len(curve) + 1) * frame_dt, curve, label=label)
  ax.set_xlabel("time (s)")
  ax.set_ylabel("positional MSE (m$^2$)")
  ax.set_yscale("log")
  ax.set_title(title)
  ax.legend()
  fig.tight_layout()
  fig.savefig(path, dpi=100)
  plt.close(fig)


def _read_csv(path: str) -> list[dict]:
  if not os.path.exists(path):
    return []
  with open(path, newline="") as f:
    return list(csv.DictReader(f))


def _write_csv(path: str, rows: Sequence[dict]):
  if not rows:
    return
  with open(path, "w", newline="") as f:
    writer = csv.DictWriter(f, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)


def evaluate(workdir: str, data_dir: str, out_dir: str, *,
             max_trajectories: int | None = None, timing_repeats: int = 3,
             checkpoint_errors: bool = True,
             checkpoint_trajectories: int | None = None) -> dict[str, Any]:
  """Writes the paper's figures, numbers and a report for a trained run.

  Args:
    max_trajectories: evaluate the first test trajectories only.
    timing_repeats: repeats of each Table 2 timing (median reported).
    checkpoint_errors: also roll out the named checkpoints (Fig. 5).
    checkpoint_trajectories: test trajectories for Fig. 5 (default: as
      many as the rest of the evaluation).
  """
  os.makedirs(out_dir, exist_ok=True)
  test_path = data.split_path(data_dir, "test")
  config, problem, trainer, state, step = load_run(workdir, data_dir)
  c = config.train.input_frames
  summary: dict[str, Any] = {"workdir": workdir, "data": data_dir,
                             "step": step, "device": str(jax.devices()[0])}

  # Figs. 3-4: training curves.
  log = _read_csv(os.path.join(workdir, "metrics.csv"))
  if log:
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
      fig.tight_layout()
      fig.savefig(os.path.join(out_dir, f"{name}.png"), dpi=100)
      plt.close(fig)

  # Figs. 6-9 and per-trajectory metrics with the latest checkpoint.
  results = rollout_split(trainer, state, problem, test_path, c,
                          max_trajectories)
  frame_dt = results[0]["trajectory"].scene.frame_dt
  curves = breakdown(results)
  titles = {"fig6_obstacles": "obstacle count", "fig7_particles":
            "particle count", "fig8_shape": "obstacle shape",
            "fig9_position": "rectangle position x (m)"}
  for fig, groups in curves.items():
    if groups:
      _plot_curves(groups, frame_dt, titles[fig],
                   os.path.join(out_dir, f"{fig}.png"))
  per_trajectory = [{
      "index": r["index"], "name": r["name"], "group": r["group"],
      "obstacles": r["obstacles"], "particles": r["particles"],
      "mean_mse": float(np.mean(r["mse"])),
      "final_mse": float(r["mse"][-1]),
      "final_runout_error": float(r["runout_error"][-1]),
      "deposit_error": r["deposit_error"]} for r in results]
  _write_csv(os.path.join(out_dir, "trajectories.csv"), per_trajectory)
  summary["test_mse"] = float(np.mean([r["mse"] for r in results]))
  summary["curves"] = {fig: {k: v.tolist() for k, v in g.items()}
                       for fig, g in curves.items()}

  # Fig. 5: test error of the named and latest checkpoints.
  errors = {}
  if checkpoint_errors:
    named = set(config.checkpoint.named_steps) | {step}
    for s in checkpoint_steps(workdir):
      if s in named:
        if s == step:
          res = results[:checkpoint_trajectories]
        else:
          _, _, tr, st, _ = load_run(workdir, data_dir, s)
          res = rollout_split(tr, st, problem, test_path, c,
                              checkpoint_trajectories or max_trajectories)
        errors[s] = float(np.mean([r["mse"] for r in res]))
    if errors:
      fig, ax = plt.subplots(figsize=(5, 3.5))
      ax.plot(list(errors), list(errors.values()), "o-")
      ax.set_xlabel("training step")
      ax.set_ylabel("test positional MSE (m$^2$)")
      ax.set_yscale("log")
      fig.tight_layout()
      fig.savefig(os.path.join(out_dir, "fig5_test_error.png"), dpi=100)
      plt.close(fig)
  summary["checkpoint_test_mse"] = errors
  summary["checkpoint_trajectories"] = (checkpoint_trajectories or
                                        len(results))

  # Table 2.
  rows = table2(trainer, state, problem, results, c, timing_repeats)
  _write_csv(os.path.join(out_dir, "table2.csv"), rows)
  summary["table2"] = rows
  mpm_io.write_json(os.path.join(out_dir, "summary.json"), summary)
  with open(os.path.join(out_dir, "report.md"), "w") as f:
    f.write(report(summary, per_trajectory))
  return summary


def report(summary: dict, per_trajectory: Sequence[dict]) -> str:
  """The Markdown report of an evaluation."""
  lines = [
      "# Evaluation", "",
      f"Run `{summary['workdir']}` at step {summary['step']}, test split of "
      f"`{summary['data']}`, on {summary['device']}.", "",
      f"Mean positional MSE over all test trajectories, particles and steps: "
      f"**{summary['test_mse']:.3e} m^2**.", "",
      "## Test error by checkpoint (Fig. 5)", "",
      f"Over the first {summary['checkpoint_trajectories']} test "
      "trajectories.", "",
      "| step | test MSE (m^2) |", "|---|---|"]
  lines += [f"| {s} | {e:.3e} |" for s, e in
            summary["checkpoint_test_mse"].items()]
  lines += ["", "## Breakdowns (Figs. 6-9): mean MSE over time (m^2)", "",
            "| figure | label | mean MSE | final MSE |", "|---|---|---|---|"]
  for fig, groups in summary["curves"].items():
    for label, curve in groups.items():
      lines.append(f"| {fig} | {label} | {np.mean(curve):.3e} | "
                   f"{curve[-1]:.3e} |")
  lines += ["", "## Table 2: seconds per simulation, this hardware, one run",
            "", "| group | particles | obstacles | frames | MPM (s) | GNS (s) "
            "| MPM/GNS | GNS MSE (m^2) |", "|---|---|---|---|---|---|---|---|"]
  for r in summary["table2"]:
    lines.append(f"| {r['group']} | {r['particles']} | {r['obstacles']} | "
                 f"{r['frames']} | {r['mpm_s']:.2f} | {r['gns_s']:.2f} | "
                 f"{r['speedup']:.2f} | {r['gns_mse']:.2e} |")
  lines += [
      "", "The paper's Table 2 reports 17-23 s for its MPM and 0.03-0.05 s for "
      "its GNS on a V100 GPU, without saying how the GNS time was taken. Here "
      "both run on the same device in the same process: the MPM is a compiled "
      "JAX solver (seconds per trajectory on one CPU), and the GNS pays for "
      "M message-passing steps of dense layers over every edge at every frame, "
      "which a CPU does at tens of GFLOP/s. See docs/results.md.", "",
      "## Per trajectory", "",
      "| # | group | particles | mean MSE | final runout error (m) | "
      "deposit error (m) |", "|---|---|---|---|---|---|"]
  for r in per_trajectory:
    lines.append(f"| {r['index']} | {r['group']} | {r['particles']} | "
                 f"{r['mean_mse']:.2e} | {r['final_runout_error']:.4f} | "
                 f"{r['deposit_error']:.4f} |")
  return "\n".join(lines) + "\n"


def constant_velocity_comparison(workdir: str, data_dir: str, *,
                                 num_windows: int = 256,
                                 rollout_steps: int = 50) -> dict[str, float]:
  """The model against the constant-velocity baseline on the test split.

  One-step: MSE of normalised acceleration on ``num_windows`` test windows
  (no noise); constant velocity predicts zero acceleration. Rollouts:
  positional MSE over the first ``rollout_steps`` steps of every test
  trajectory.
  """
  config, problem, trainer, state, step = load_run(workdir, data_dir)
  c = config.train.input_frames
  test_path = data.split_path(data_dir, "test")
  model_loss, baseline_loss = [], []
  stats = problem.stats
  with data.WindowDataset(test_path, input_frames=c, seed=1) as ds:
    for k in range(0, num_windows, config.train.batch_size):
      windows = [ds[k + i] for i in range(config.train.batch_size)]
      batch = batching.make_batch(windows, problem.spec,
                                  config.train.node_bucket)
      arrays = trainer.batch_arrays(batch, None, noise=False)
      model_loss.append(float(trainer.eval_loss(state.params, *arrays)))
      inputs, target, _, moving = (np.asarray(a) for a in arrays[:4])
      acc = target - 2 * inputs[:, -1] + inputs[:, -2]
      want = (acc - np.asarray(stats.acc_mean)) / np.asarray(stats.acc_std)
      zero_pred = -np.asarray(stats.acc_mean) / np.asarray(stats.acc_std)
      err = np.sum((want - zero_pred)**2, -1) * moving
      baseline_loss.append(float(np.mean(
          err.sum(-1) / np.maximum(moving.sum(-1), 1) / 2)))
  rollout_mse, constant_mse = [], []
  for t in data.trajectories(test_path):
    steps = min(rollout_steps, len(t.positions) - c)
    pred = rollout_lib.rollout_trajectory(trainer.model, state.params, t,
                                          problem, steps, c)
    truth = t.positions[c:c + steps]
    v = t.positions[c - 1] - t.positions[c - 2]
    constant = t.positions[c - 1][None] + v[None] * np.arange(
        1, steps + 1)[:, None, None]
    rollout_mse.append(float(np.mean(metrics.positional_mse(pred, truth))))
    constant_mse.append(float(np.mean(metrics.positional_mse(constant,
                                                             truth))))
  return {
      "step": step, "windows": len(model_loss) * config.train.batch_size,
      "trajectories": len(rollout_mse), "rollout_steps": rollout_steps,
      "one_step_loss": float(np.mean(model_loss)),
      "one_step_loss_constant_velocity": float(np.mean(baseline_loss)),
      "rollout_mse_m2": float(np.mean(rollout_mse)),
      "rollout_mse_constant_velocity_m2": float(np.mean(constant_mse)),
      "rollout_mse_per_trajectory": rollout_mse,
      "rollout_mse_constant_velocity_per_trajectory": constant_mse,
  }
