"""How much of training's draw is flow and how much is rest, per dataset.

For each training split and motion weighting p: the share of the windows,
drawn as ``gnsjax.data.WindowDataset`` draws them (weight (1 - p) + p m /
mean(m), m a window's mean sand speed over its span of 9 frames at stride
3), whose sand moves faster than 5 cm/s, slower than 1 cm/s and slower than
0.2 cm/s.

  python docs/results/window_motion.py data/small1000:0.5 \
      data/small1000_long:0.5,0.75,0.9
"""
import sys

import numpy as np

from gnsjax import data

FRAME_DT = 0.0025  # s between stored frames


def main(specs):
  print("| training split | motion weighting | > 5 cm/s | < 1 cm/s "
        "| < 0.2 cm/s |")
  print("|---|---:|---:|---:|---:|")
  for spec in specs:
    path, weightings = spec.split(":")
    dataset = data.WindowDataset(data.split_path(path, "train"),
                                 input_frames=9, frame_stride=3)
    speed = dataset._window_motion() / FRAME_DT * 100  # cm/s
    for p in map(float, weightings.split(",")):
      w = (1 - p) + p * speed / speed.mean()
      w /= w.sum()
      print(f"| {path} | {p:.2f} | {w[speed > 5].sum():.3f} | "
            f"{w[speed < 1].sum():.3f} | {w[speed < 0.2].sum():.3f} |")


if __name__ == "__main__":
  main(sys.argv[1:])
