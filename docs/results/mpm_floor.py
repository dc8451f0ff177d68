"""The MPM against itself: how far apart two MPM runs of the same test scene
end when they differ by far less than the data resolve. The learned
simulator is scored against one such run (the stored trajectory); what the
MPM cannot reproduce of itself bounds what any model can be asked to
(docs/gns_log.md, "The MPM against itself").

Each test scene of data/small1000 is run again by ``mpm.simulate`` with its
initial particles moved by a random offset of std SIGMA in each coordinate
(default 1 micrometre: a ten-thousandth of the 10 mm spacing). With SIGMA =
0 the rerun is the stored trajectory bit for bit (checked on three scenes),
so the offset alone parts the runs. The run is scored against the stored
trajectory with the evaluation's metrics (``gnsjax.metrics``, as
``experiments.studies.evaluation.score`` calls them) on the frames a
learned rollout predicts: the mean positional MSE over those frames, the
final front and deposit-profile errors, the kinetic-energy ratio over the
last 0.25 s and whether the end speed passes the issue's bound, max(2x the
stored run's, 1 cm/s).

  python docs/results/mpm_floor.py --out=OUT.csv [--sigma=1e-6]
      [--test=data/small1000/test.h5] [--only=5,18] [--seed=0]

Prints per trajectory and per group; writes one CSV row per trajectory.
About 1.5 s a scene on one core, after a compilation per particle bucket.
"""
import csv

from absl import app
from absl import flags
import numpy as np

from experiments.configs import small
from gnsjax import data
from gnsjax import metrics
from gnsjax import rollout as rollout_lib
from mpm import dataset
from mpm import geometry
from mpm import simulation

flags.DEFINE_string("out", None, "CSV of one row per trajectory.",
                    required=True)
flags.DEFINE_float("sigma", 1e-6, "std (m) of the initial offset.")
flags.DEFINE_string("test", "data/small1000/test.h5", "the test split.")
flags.DEFINE_list("only", [], "trajectory indices (default: all).")
flags.DEFINE_integer("seed", 0, "seed of the offsets.")
flags.DEFINE_string("figure", None, "PNG of the last frames of both runs "
                    "and their deposit profiles, one panel per scene (for "
                    "a few scenes, with --only).")
FLAGS = flags.FLAGS

_TRAIN = small.get_config().train  # the small config's learned rollout
INPUT_FRAMES, FRAME_STRIDE = _TRAIN.input_frames, _TRAIN.frame_stride
REST_WINDOW_S = 0.25  # s: the evaluation's (experiments/studies/evaluation)


def plot(panels, path):
  """The stored and the moved run's last frames, with their deposit
  profiles (the top of the sand per bin, as ``metrics.deposit_error``)."""
  import matplotlib  # pylint: disable=g-import-not-at-top
  matplotlib.use("Agg")
  import matplotlib.pyplot as plt  # pylint: disable=g-import-not-at-top
  fig, axes = plt.subplots(len(panels), 1, squeeze=False,
                           figsize=(9, 3.2 * len(panels)))
  for ax, (index, moved, stored, error, width) in zip(axes[:, 0], panels):
    lo = min(moved[:, 0].min(), stored[:, 0].min())
    hi = max(moved[:, 0].max(), stored[:, 0].max())
    edges = np.arange(lo, hi + width, width)
    for x, label, color in ((stored, "stored MPM", "k"),
                            (moved, f"MPM, moved {FLAGS.sigma:g} m", "C3")):
      ax.scatter(x[:, 0], x[:, 1], s=3, color=color, label=label)
      ax.step(edges[:-1], metrics.deposit_profile(x, edges), where="post",
              color=color, lw=0.8)
    ax.set(title=f"test {index}: last frame, deposit error {error:.3f} m",
           xlabel="x (m)", ylabel="y (m)", aspect="equal")
    ax.legend(loc="upper left", fontsize=7)
  fig.tight_layout()
  fig.savefig(path, dpi=110)


def main(_):
  rng = np.random.default_rng(FLAGS.seed)
  only = {int(i) for i in FLAGS.only}
  rows, panels = [], []
  for index, t in enumerate(data.trajectories(FLAGS.test)):
    if only and index not in only:
      continue
    x0 = geometry.granular_particles(t.scene)
    x0 = x0 + rng.normal(0.0, FLAGS.sigma, x0.shape)
    again = np.asarray(simulation.simulate_setups(
        [simulation.setup(t.scene, x0)])[0].positions)
    frames = rollout_lib.predicted_frame_indices(len(t.positions),
                                                 INPUT_FRAMES, FRAME_STRIDE)
    pred, truth = again[frames], np.asarray(t.positions)[frames]
    dt = t.scene.frame_dt
    speed, mpm_speed = (metrics.final_speed(x, frames * dt)
                        for x in (pred, truth))
    row = {
        "index": index, "group": dataset.group_of(t.scene.name),
        "particles": truth.shape[1],
        "mean_mse": float(np.mean(metrics.positional_mse(pred, truth))),
        "front_error_relative": metrics.front_error_relative(
            pred[-1], truth[-1], np.asarray(t.positions[0])),
        "deposit_error": metrics.deposit_error(
            pred[-1], truth[-1], 2 * t.scene.granular.spacing),
        # the rest targets, as the evaluation scores them
        "kinetic_energy_ratio": metrics.kinetic_energy_ratio(
            pred, np.asarray(t.positions), frames * dt,
            np.arange(len(t.positions)) * dt, REST_WINDOW_S),
        "final_speed": speed, "mpm_final_speed": mpm_speed,
        "over_speed_bound": bool(speed > metrics.rest_speed_bound(
            mpm_speed)),
        "first_frame_offset": float(np.max(np.abs(again[0] -
                                                  t.positions[0]))),
    }
    rows.append(row)
    panels.append((index, pred[-1], truth[-1], row["deposit_error"],
                   2 * t.scene.granular.spacing))
    print(f"test {index:3d} {row['group']:>15s}: MSE {row['mean_mse']:.2e} "
          f"front {row['front_error_relative']:.3f} deposit "
          f"{row['deposit_error']:.3f} m KE ratio "
          f"{row['kinetic_energy_ratio']:.2f}", flush=True)

  if FLAGS.figure:
    plot(panels, FLAGS.figure)
  with open(FLAGS.out, "w", newline="") as f:
    out = csv.DictWriter(f, fieldnames=list(rows[0]))
    out.writeheader()
    out.writerows(rows)
  groups = sorted({r["group"] for r in rows})
  for group in ["all"] + groups:
    sel = [r for r in rows if group == "all" or r["group"] == group]
    col = lambda k: np.array([r[k] for r in sel], float)
    fronts = col("front_error_relative")
    over_speed, over_energy = metrics.over_rest_targets(
        col("final_speed"), col("mpm_final_speed"),
        col("kinetic_energy_ratio"))
    print(f"{group:>15s} ({len(sel):3d}): MSE "
          f"{col('mean_mse').mean():.2e}, front median "
          f"{np.median(fronts):.3f} worst {fronts.max():.3f}, deposit "
          f"median {np.median(col('deposit_error')):.3f} m, "
          f"over 15% {(fronts > 0.15).sum()}, KE ratio over 10 "
          f"{over_energy.sum()}, over the speed bound {over_speed.sum()}")


if __name__ == "__main__":
  app.run(main)
