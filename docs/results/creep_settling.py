"""What a learned deposit's creep after rest is made of.

For the stability table's three 2000-step cases (``experiments.studies.
stability``, moving starts with no obstacle, a semicircle, a triangle) and
a model, the learned rollout's sand from its rest time to the end (15.2 s),
against the MPM's on the same scene to 1.5 s (its sand rests by 1 s):
- the creep (mean particle displacement over time, the table's column)
  and the part of it that is the whole heap moving (its centre's
  displacement over time): a slide moves the centre, jitter does not;
- the sand's mean height at rest and at the end: a heap that settles sinks;
- the median distance to each particle's nearest neighbour at rest and at
  the end: a heap that compacts closes up (the MPM's at 1.5 s beside it).

  python docs/results/creep_settling.py experiments/pretrained/small
"""
import sys

import numpy as np

import mpm
from experiments.studies import stability
from gnsjax import metrics
from gnsjax import run as run_lib


def nearest_neighbour(positions):
  """Median distance (m) from each particle [N, 2] to its nearest one."""
  d = np.linalg.norm(positions[:, None] - positions[None], axis=-1)
  np.fill_diagonal(d, np.inf)
  return float(np.median(d.min(axis=1)))


def main(model_dir):
  run = run_lib.load_run(model_dir)
  cases = stability.gns_cases(run.config.dataset.spacing)[:3]
  print("| case | creep (mm/s) | the centre's (mm/s) | height at rest / "
        "end / MPM's (cm) | nearest neighbour at rest / end / MPM's "
        "(mm) |")
  print("|---|---:|---:|---|---|")
  for case in cases:
    outcome = stability.run_gns(case, run)
    x = np.asarray(outcome.positions, np.float64)
    times = outcome.frames * outcome.scene.frame_dt
    rest = metrics.rest_time(x, times, stability.REST_SPEED)
    i = int(np.searchsorted(times, rest))
    creep = metrics.creep(x, times, rest)
    centre = (np.linalg.norm(np.mean(x[-1] - x[i], axis=0))
              / (times[-1] - times[i]))
    reference = np.asarray(mpm.simulate(outcome.scene).positions[-1],
                           np.float64)
    print(f"| {case.name} | {1e3 * creep:.2f} | {1e3 * centre:.2f} | "
          f"{1e2 * x[i, :, 1].mean():.1f} / {1e2 * x[-1, :, 1].mean():.1f}"
          f" / {1e2 * reference[:, 1].mean():.1f} | "
          f"{1e3 * nearest_neighbour(x[i]):.1f} / "
          f"{1e3 * nearest_neighbour(x[-1]):.1f} / "
          f"{1e3 * nearest_neighbour(reference):.1f} |", flush=True)


if __name__ == "__main__":
  main(sys.argv[1])
