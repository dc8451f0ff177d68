"""How much sand drains off the rectangle high on the ramp (the test group
rectangle_x1.3) late in the avalanche: the MPM's stored 10 mm trajectories,
a learned model's rollouts and, for a few scenes, the MPM run again at finer
particle spacings (the output in docs/gns_log.md, "A third stage from the
shipped soup, and the drain off the high rectangle").

Prints, per scene, the share of the sand above x = 1.15 m (on or behind the
rectangle) at frames 405 (1.0 s) and 597 (1.5 s), and their difference, the
share that drained in the last half second; then the means over the group.

  python docs/results/obstacle_drain.py MODEL_DIR [SPACINGS [INDICES]]

e.g. experiments/pretrained/small 0.005,0.0025 18,81,88 (about 8 min on one
core: the MPM at 2.5 mm takes 40-80 s a scene).
"""
import sys

import numpy as np

import mpm
from gnsjax import metrics
from gnsjax import rollout as rollout_lib
from gnsjax import run as run_lib
from mpm import dataset
from mpm import io as mpm_io
from mpm import resolution

X_CUT = 1.15  # m: the rectangle's foot is at x = 1.3 m
FRAMES = (405, 597)

workdir = sys.argv[1]
spacings = [float(s) for s in sys.argv[2].split(",")] if len(
    sys.argv) > 2 else []
finer_indices = {int(i) for i in sys.argv[3].split(",")} if len(
    sys.argv) > 3 else set()
run = run_lib.load_run(workdir)


def shares(positions_at) -> tuple[float, float, float]:
  """(share above X_CUT at each of FRAMES, the drop between them)."""
  a, b = (1 - metrics.mass_past(positions_at(f), [X_CUT])[0] for f in FRAMES)
  return a, b, a - b


rows = {}
for index, t in enumerate(mpm_io.read_trajectories("data/small1000/test.h5")):
  if dataset.group_of(t.scene.name) != "rectangle_x1.3":
    continue
  x = np.asarray(rollout_lib.rollout_trajectory(run.model, run.params, t,
                                                run.problem).positions)
  step_of = {f: s for s, f in enumerate(rollout_lib.predicted_frame_indices(
      len(t.positions), run.problem.input_frames, run.problem.frame_stride))}
  stored = f"mpm {t.scene.granular.spacing * 1000:g} mm"
  measured = {stored: shares(lambda f: np.asarray(t.positions[f])),
              workdir: shares(lambda f: x[step_of[f]])}
  if index in finer_indices:
    for spacing in spacings:
      q = np.asarray(mpm.simulate(resolution.at_spacing(t.scene,
                                                        spacing)).positions)
      label = f"mpm {spacing * 1000:g} mm"
      measured[label] = shares(lambda f: q[f])
  for label, value in measured.items():
    rows.setdefault(label, []).append(value)
    print(f"test {index:3d} {label:>30s}: "
          f"{value[0]:.3f} -> {value[1]:.3f} (drained {value[2]:.3f})",
          flush=True)
for label, values in rows.items():
  mean = np.mean(values, axis=0)
  print(f"mean of {len(values):2d} {label:>30s}: {mean[0]:.3f} -> "
        f"{mean[1]:.3f} (drained {mean[2]:.3f})")
