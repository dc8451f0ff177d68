"""Scores of several evaluations on the same test trajectories.

  python docs/results/paired_subset.py N DIR_A DIR_B ...

Each DIR is an `experiments.evaluate --out` folder with its
`trajectories.csv`; only the trajectories every one of them evaluated with
index below N are scored (an evaluation with `--max_trajectories=N` takes
the first N, which cycle the test split's 7 groups), so a short
evaluation is compared with the full ones on the same scenes. Prints one
row per DIR: mean whole-rollout MSE, median and worst front error, fronts
over 10% and 15%, median kinetic-energy ratio and how many over 10, and
how many trajectories end faster than max(2x the MPM's, 1 cm/s) (both
`gnsjax.metrics.over_rest_targets`). The last column is each MSE against
the first DIR's, paired trajectory by trajectory: the mean difference
and twice its standard error, as percentages of the first's MSE; a
difference inside the +-2 s.e. is within what the draw of the scenes
moves.
"""

import csv
import sys

import numpy as np

from gnsjax import metrics


def _rows(folder: str) -> dict:
  with open(f"{folder}/trajectories.csv", newline="") as f:
    return {int(r["index"]): r for r in csv.DictReader(f)}


def main(argv):
  limit, folders = int(argv[1]), argv[2:]
  tables = [_rows(d) for d in folders]
  common = sorted(set.intersection(*(set(t) for t in tables)))
  common = [i for i in common if i < limit]
  print(f"{len(common)} trajectories: {common[0]}..{common[-1]}")
  print("| evaluation | MSE | front median / worst | over 10% / 15% "
        "| KE ratio median; over 10 | over the speed bound "
        "| MSE vs the first (paired) |")
  print("|---|---|---|---|---|---|---|")
  first_mse = None
  for folder, table in zip(folders, tables):
    col = lambda k: np.array([float(table[i][k]) for i in common])
    mse = col("mean_mse")
    if first_mse is None:
      first_mse, versus = mse, "-"
    else:
      versus = "%+.1f%% +- %.1f%%" % metrics.paired_difference(
          mse, first_mse)
    front, ke = col("front_error_relative"), col("kinetic_energy_ratio")
    over_speed, over_energy = metrics.over_rest_targets(
        col("final_speed"), col("mpm_final_speed"), ke)
    print(f"| {folder} | {mse.mean():.2e} | "
          f"{np.median(front):.1%} / {front.max():.0%} | "
          f"{(front > 0.1).sum()} / {(front > 0.15).sum()} | "
          f"{np.median(ke):.2f}; {over_energy.sum()} | "
          f"{over_speed.sum()} | {versus} |")


if __name__ == "__main__":
  main(sys.argv)
