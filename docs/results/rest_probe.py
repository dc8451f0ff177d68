"""How still models hold the MPM's deposit, and what their velocity gate says.

For each model: test trajectories 0, 12, ..., 96 of data/small1000 rolled
out with the solid constraint for 200 learned steps (1.5 s) from their last
frames (the MPM's deposit); the sand's mean speed over the last 5 steps and
its mean drift from the deposit, medians over the nine. For a model with a
velocity gate (``config.model.velocity_gate``), also the gate g = sigmoid(z)
on the MPM's own frames, median over the sand of the same nine: early in
the flow (inputs ending at frame 75) and at the deposit (the last frames),
where sand below 1 cm/s counts as resting.

  python docs/results/rest_probe.py MODEL_DIR...
"""
import itertools
import sys

import jax
import numpy as np

from gnsjax import data
from gnsjax import features
from gnsjax import rollout
from gnsjax import run as run_lib
from gnsjax import simulator

STEPS = 200
TRAJECTORIES = range(0, 100, 12)


def gate(run, t, start):
  """(gate [n], speed [n] in m/s) of the sand of window ``start``."""
  c, k, problem = run.problem.input_frames, run.problem.frame_stride, run.problem
  scene = rollout.trajectory_nodes(t, c, k, problem.boundary_particles,
                                   problem.sdf_spacing, start)
  last = scene.window[-1].astype(np.float64)
  senders, receivers = np.nonzero(
      np.sum((last[:, None] - last[None]) ** 2, -1) < problem.radius**2)
  node_f = features.node_features(scene.window, problem.context.stats,
                                  scene.solids,
                                  run.model.seen_solid_range(problem.radius))
  edge_f = features.edge_features(scene.window[-1], senders, receivers,
                                  problem.radius)
  out = run.model.apply(run.params, node_f, scene.types, edge_f, senders,
                        receivers)
  g = np.asarray(jax.nn.sigmoid(out[:, 2]))[scene.moving]
  speed = np.linalg.norm(scene.window[-1] - scene.window[-2], axis=-1)
  return g, speed[scene.moving] / (0.0025 * k)


def main(model_dirs):
  path = data.split_path("data/small1000", "test")
  chosen = [t for i, t in enumerate(itertools.islice(
      data.trajectories(path), TRAJECTORIES.stop)) if i in TRAJECTORIES]
  print("| model | held: speed after 1.5 s (mm/s) | drift (mm) | gate: "
        "flowing (frame 75) / resting sand at the deposit |")
  print("|---|---:|---:|---|")
  for model_dir in model_dirs:
    run = run_lib.load_run(model_dir)
    c, k = run.problem.input_frames, run.problem.frame_stride
    speeds, drifts, early, rest = [], [], [], []
    for t in chosen:
      start = len(t.positions) - 1 - (c - 1) * k
      out = rollout.rollout_trajectory(run.model, run.params, t, run.problem,
                                       n_steps=STEPS, start=start)
      p = np.asarray(out.positions)
      speeds.append(np.linalg.norm(p[-1] - p[-6], axis=-1).mean()
                    / (5 * 0.0025 * k))
      drifts.append(np.linalg.norm(p[-1] - t.positions[-1], axis=-1).mean())
      if run.model.velocity_gate:
        early.append(gate(run, t, 75 - (c - 1) * k)[0])
        g, speed = gate(run, t, start)
        rest.append(g[speed < 0.01])
    gates = (f"{np.median(np.concatenate(early)):.3f} / "
             f"{np.median(np.concatenate(rest)):.3f}" if early else "no gate")
    print(f"| {model_dir} | {np.median(speeds) * 1e3:.2f} | "
          f"{np.median(drifts) * 1e3:.1f} | {gates} |", flush=True)


if __name__ == "__main__":
  main(sys.argv[1:])
