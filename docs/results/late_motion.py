"""Where the kinetic energy of a learned deposit's last 0.25 s comes from.

For one test trajectory of data/small1000 and a model, the rollout with the
constraint (as the evaluation makes it) against the MPM's frames at the
learned stride, over the last 0.25 s:
- the kinetic-energy ratio (mean squared speed, learned over MPM);
- the mean speed per learned step, both simulators (a deposit that rests
  late shows a falling learned speed; one that jitters, a flat one);
- the fastest particles: their top and mean speed, how far they got
  (net, against the path they took: a particle that hops in place moves
  far and gets nowhere), where they end and where the MPM's same
  particles end, and their share of the energy.

  python docs/results/late_motion.py experiments/runs/s1pf3_ft_avg3 85
"""
import itertools
import sys

import numpy as np

from gnsjax import data
from gnsjax import rollout
from gnsjax import run as run_lib

LAST_S = 0.25
SHOWN = 8


def main(model_dir, index):
  run = run_lib.load_run(model_dir)
  path = data.split_path("data/small1000", "test")
  t = next(itertools.islice(data.trajectories(path), index, None))
  out = rollout.rollout_trajectory(run.model, run.params, t, run.problem)
  k = run.problem.frame_stride
  dt = t.scene.frame_dt * k
  n = int(round(LAST_S / dt)) + 1
  learned = np.asarray(out.positions)[-n:]
  frames = rollout.predicted_frame_indices(len(t.positions),
                                          run.problem.input_frames, k)
  truth = np.asarray(t.positions)[frames][-n:]
  speed = np.linalg.norm(np.diff(learned, axis=0), axis=-1) / dt   # [n-1, N]
  speed_mpm = np.linalg.norm(np.diff(truth, axis=0), axis=-1) / dt
  print(f"{t.scene.name}: {learned.shape[1]} particles, last {n - 1} "
        f"learned steps of {dt * 1e3:.1f} ms")
  print(f"kinetic-energy ratio {np.mean(speed**2) / np.mean(speed_mpm**2):.1f}")
  print("mean speed per step (cm/s), learned:",
        [round(float(x), 2) for x in 100 * speed.mean(1)])
  print("mean speed per step (cm/s), MPM:    ",
        [round(float(x), 2) for x in 100 * speed_mpm.mean(1)])
  fastest = np.argsort(-speed.max(0))[:SHOWN]
  share = (speed[:, fastest]**2).sum() / (speed**2).sum()
  print(f"the {SHOWN} fastest particles hold {share:.0%} of the energy:")
  for i in fastest:
    net = np.linalg.norm(learned[-1, i] - learned[0, i])
    path_length = speed[:, i].sum() * dt
    print(f"  {i:4d}: top {speed[:, i].max():.3f} m/s, mean "
          f"{speed[:, i].mean():.3f} m/s, {100 * net:.1f} cm net of "
          f"{100 * path_length:.1f} cm, ends at {learned[-1, i].round(3)} "
          f"(MPM {truth[-1, i].round(3)})")


if __name__ == "__main__":
  main(sys.argv[1], int(sys.argv[2]))
