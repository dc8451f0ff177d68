"""Where a model's fronts go wrong: its worst test trajectories, rolled out.

For each test trajectory INDEX of data/small1000 (or DATA), the model is
rolled out over the whole 1.5 s with the solid constraint. Top row: the
front (the 1% quantile of the sand's x, `gnsjax.metrics.runout`) over
time, learned against the MPM's. Middle row: the two at the moment the
learned front leaves the MPM's by 5 cm (or the last frame). Bottom row:
the last frame. Printed per trajectory: the final fronts and the mean
speeds over the last 5 learned steps.

  python docs/results/worst_fronts.py experiments/pretrained/small \
      docs/results/ft_rcr_pf3_avg3_all/worst_fronts.png 13,27,96,8,89,25
  python docs/results/worst_fronts.py MODEL OUT.png 85,57 data/small_select
(the last argument: another dataset directory, whose test split is used)
"""
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # pylint: disable=g-import-not-at-top
import numpy as np  # pylint: disable=g-import-not-at-top

from experiments import figures  # pylint: disable=g-import-not-at-top
from gnsjax import data  # pylint: disable=g-import-not-at-top
from gnsjax import metrics  # pylint: disable=g-import-not-at-top
from gnsjax import rollout  # pylint: disable=g-import-not-at-top
from gnsjax import run as run_lib  # pylint: disable=g-import-not-at-top

PARTING_M = 0.05


def main(model_dir: str, out: str, indices: list[int],
         data_dir: str = "data/small1000"):
  run = run_lib.load_run(model_dir)
  trajectories = list(data.trajectories(
      data.split_path(data_dir, "test")))
  c, k = run.problem.input_frames, run.problem.frame_stride
  fig, axes = plt.subplots(3, len(indices), squeeze=False,
                           figsize=(4.2 * len(indices), 8.4))
  for column, i in zip(axes.T, indices):
    t = trajectories[i]
    out_i = rollout.rollout_trajectory(run.model, run.params, t, run.problem,
                                       project=True)
    frames = rollout.predicted_frame_indices(len(t.positions), c, k)
    true, pred = t.positions[frames], np.asarray(out_i.positions)
    times = frames * t.scene.frame_dt
    front_true, front_pred = metrics.runout(true), metrics.runout(pred)
    speed = lambda x: metrics.final_speed(x, times)
    shapes = "+".join(o.shape for o in t.scene.obstacles) or "none"
    print(f"test {i} ({shapes}): front MPM {front_true[-1]:.3f} m, "
          f"learned {front_pred[-1]:.3f} m; end speed MPM "
          f"{100 * speed(true):.2f} cm/s, learned {100 * speed(pred):.2f}")
    column[0].plot(times, front_true, "k", label="MPM")
    column[0].plot(times, front_pred, "r", label="GNS")
    column[0].set(title=f"test {i} ({shapes})", xlabel="time (s)",
                  ylabel="front x (m)")
    column[0].legend()
    apart = np.flatnonzero(np.abs(front_pred - front_true) > PARTING_M)
    for ax, j in ((column[1], apart[0] if len(apart) else -1),
                  (column[2], -1)):
      figures.draw_scene(ax, t.scene)
      ax.scatter(true[j, :, 0], true[j, :, 1], s=2, c="k", label="MPM")
      ax.scatter(pred[j, :, 0], pred[j, :, 1], s=2, c="r", label="GNS")
      ax.set(xlim=(0.0, 1.4), ylim=(0.0, 0.6), title=f"{times[j]:.2f} s")
  fig.tight_layout()
  fig.savefig(out, dpi=80)


if __name__ == "__main__":
  main(sys.argv[1], sys.argv[2], [int(i) for i in sys.argv[3].split(",")],
       *sys.argv[4:5])
