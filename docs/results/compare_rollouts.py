"""Two models' rollouts of one test trajectory beside the MPM's (the ramp
and the obstacles drawn), at four frames up to the last, and their sand's
mean speed near the end (the pictures docs/gns_log.md cites from
rest_cleanrest_avg5_all/, ft_rcr_clean10_avg3_all/ and
ft_rcr_quiet_avg3_all/):

  python docs/results/compare_rollouts.py INDEX OUT.png MODEL_A MODEL_B \
      [YMAX [XMIN XMAX]]

e.g. 57 docs/results/rest_cleanrest_avg5_all/test57_against_shipped.png
experiments/runs/rest_cleanrest_avg5 experiments/pretrained/small 0.6, and
12 docs/results/ft_rcr_clean10_avg3_all/test12_against_scratch.png
experiments/runs/ft_rcr_clean10_avg3 experiments/runs/rest_cleanrest_avg5 0.8.
"""
import itertools
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # pylint: disable=wrong-import-position
import numpy as np  # pylint: disable=wrong-import-position

from experiments import figures  # pylint: disable=wrong-import-position
from gnsjax import rollout as rollout_lib  # pylint: disable=wrong-import-position
from gnsjax import run as run_lib  # pylint: disable=wrong-import-position
from mpm import io as mpm_io  # pylint: disable=wrong-import-position

index, out_png, *models = sys.argv[1:5]
ymax = float(sys.argv[5]) if len(sys.argv) > 5 else 0.6
xlim = tuple(map(float, sys.argv[6:8])) if len(sys.argv) > 7 else (0, 1.65)
t = next(itertools.islice(
    mpm_io.read_trajectories("data/small1000/test.h5"), int(index), None))
fig, axes = plt.subplots(2, 4, figsize=(20, 7))
for row, workdir in enumerate(models):
  run = run_lib.load_run(workdir)
  x = np.asarray(rollout_lib.rollout_trajectory(run.model, run.params, t,
                                                run.problem).positions)
  frames = rollout_lib.predicted_frame_indices(
      len(t.positions), run.problem.input_frames, run.problem.frame_stride)
  speed = np.linalg.norm(np.diff(x, axis=0), axis=-1).mean(1) / (
      run.problem.frame_stride * t.scene.frame_dt)
  print(workdir, "speed (cm/s) 1, 20 and 60 steps before the end:",
        [round(100 * float(speed[i]), 2) for i in (-1, -20, -60)])
  # Is the end's mean speed a few particles' or the whole deposit's?
  last = np.sort(np.linalg.norm(x[-1] - x[-2], axis=-1) / (
      run.problem.frame_stride * t.scene.frame_dt))[::-1]
  print("  last step: fastest 5 particles (cm/s)",
        [round(100 * float(v), 1) for v in last[:5]],
        "median", round(100 * float(np.median(last)), 2))
  for ax, step in zip(axes[row], (len(x) // 3, 2 * len(x) // 3,
                                  len(x) - 30, len(x) - 1)):
    f = frames[step]
    figures.draw_scene(ax, t.scene)
    ax.scatter(*t.positions[f].T, s=3, c="k", label="MPM")
    ax.scatter(*x[step].T, s=3, c="r", label="GNS")
    ax.set_xlim(*xlim)
    ax.set_ylim(0, ymax)
    ax.set_aspect("equal")
    ax.set_title(f"{workdir.split('/')[-1]} frame {f}")
fig.savefig(out_png, dpi=70)
