"""Does the solid constraint hold the learned deposit up, or only touch it?

For every EVERY-th test trajectory of data/small1000, each model is rolled
out twice over the whole 1.5 s: with the constraint and without it. Printed
per model and rollout, as means over the trajectories:
- the sand deeper than 0.1 / 0.5 / 1 / 2 mm inside a solid at the last
  frame (the evaluation's "inside" counts only what is deeper than half a
  particle spacing, 5 mm);
- the sand's mean speed over the last 5 learned steps;
- with the constraint: the sand it pushes out per step over the last
  0.25 s, and how far (the deepest push of each step, averaged).

A model whose deposit leans on the constraint sinks without it, or moves
faster; one whose deposit only touches the surface has the same end speed
both ways and nothing deep inside.

  python docs/results/rest_contact.py 7 experiments/runs/rest_cleanrest_avg5 \
      experiments/pretrained/small
"""
import sys

import numpy as np

from experiments.studies import evaluation
from gnsjax import data
from gnsjax import metrics
from gnsjax import rollout
from gnsjax import run as run_lib

DEPTHS_M = (1e-4, 5e-4, 1e-3, 2e-3)


def deeper_than(positions, scene):
  """Fraction of the sand [N, 2] deeper than each of DEPTHS_M in a solid."""
  return [float(metrics.inside_solids(positions, scene, depth))
          for depth in DEPTHS_M]


def main(every, model_dirs):
  path = data.split_path("data/small1000", "test")
  trajectories = [t for i, t in enumerate(data.trajectories(path))
                  if i % every == 0]
  mpm = np.mean([deeper_than(t.positions[-1], t.scene)
                 for t in trajectories], 0)
  print(f"{len(trajectories)} test trajectories (every {every}th)")
  print("| model | rollout | deeper than 0.1 / 0.5 / 1 / 2 mm | end speed "
        "(cm/s) | pushed per step, last 0.25 s | mean push (um) |")
  print("|---|---|---|---|---|---|")
  print(f"| MPM | | {' / '.join(f'{100 * v:.2f}%' for v in mpm)} | | | |")
  for model_dir in model_dirs:
    run = run_lib.load_run(model_dir)
    c, k = run.problem.input_frames, run.problem.frame_stride
    for project in (True, False):
      rows = []
      for t in trajectories:
        frames = rollout.predicted_frame_indices(len(t.positions), c, k)
        times = frames * t.scene.frame_dt
        late = times >= times[-1] - evaluation.REST_WINDOW_S
        out = rollout.rollout_trajectory(run.model, run.params, t,
                                         run.problem, project=project)
        sand = out.positions.shape[1]
        rows.append(deeper_than(out.positions[-1], t.scene) + [
            metrics.final_speed(out.positions, times),
            np.mean(out.pushed[late]) / sand,
            np.mean(out.depth[late])])
      mean = np.mean(rows, 0)
      deep = " / ".join(f"{100 * v:.2f}%" for v in mean[:4])
      pushed = f"{100 * mean[5]:.2f}%" if project else ""
      depth = f"{1e6 * mean[6]:.0f}" if project else ""
      name = "constrained" if project else "free"
      print(f"| {model_dir} | {name} | {deep} | {100 * mean[4]:.2f} | "
            f"{pushed} | {depth} |")


if __name__ == "__main__":
  main(int(sys.argv[1]), sys.argv[2:])
