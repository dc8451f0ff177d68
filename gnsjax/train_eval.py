"""The evaluation a training run logs every ``eval.every_steps`` steps."""

import numpy as np

from gnsjax import data
from gnsjax import metrics as metrics_lib
from gnsjax import rollout as rollout_lib


def evaluate(trainer, state, data_dir: str, num_windows: int,
             rollout_steps: int, num_rollouts: int) -> dict:
  """One-step loss on test windows (no noise), and rollout position MSE
  against ground truth and a constant-velocity baseline.

  Args:
    trainer, state: a ``gnsjax.train.Trainer`` and its ``TrainState``.
  """
  cfg, problem = trainer.config, trainer.problem
  test_path = data.split_path(data_dir, "test")
  metrics = {}
  with data.WindowDataset(test_path, input_frames=problem.input_frames,
                          frame_stride=problem.frame_stride, seed=0) as ds:
    windows = [ds[k] for k in range(min(num_windows, len(ds)))]
  losses = []
  rows = trainer.rows(cfg.train.batch_size)
  for i in range(0, len(windows), cfg.train.batch_size):
    chunk = windows[i:i + cfg.train.batch_size]
    if len(chunk) < cfg.train.batch_size:
      break
    chunk = [chunk[r] for r in rows]
    graphs, target = trainer.batch_arrays(trainer.make_batch(chunk), None,
                                          noise=False)
    losses.append(float(trainer.eval_loss(state.params, graphs, target)))
  if losses:
    metrics["eval/one_step_loss"] = float(np.mean(losses))
  if rollout_steps > 0 and num_rollouts > 0:
    # Every process rolls out the same trajectories (the same numbers).
    params = trainer.local_params(state.params)
    errors, baseline = [], []
    for k, t in enumerate(data.trajectories(test_path)):
      if k >= num_rollouts:
        break
      frames = rollout_lib.predicted_frame_indices(
          len(t.positions), problem.input_frames, problem.frame_stride)
      frames = frames[:rollout_steps]
      pred = rollout_lib.rollout_trajectory(
          trainer.model, params, t, problem, len(frames)).positions
      truth = t.positions[frames]
      errors.append(np.mean(np.sum((pred - truth)**2, -1)))
      const = metrics_lib.constant_velocity(t.positions, frames,
                                            problem.input_frames,
                                            problem.frame_stride)
      baseline.append(np.mean(np.sum((const - truth)**2, -1)))
    metrics["eval/rollout_mse"] = float(np.mean(errors))
    metrics["eval/rollout_mse_constant_velocity"] = float(np.mean(baseline))
  return metrics
