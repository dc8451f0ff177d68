"""A sand block window the tests write themselves.

The shared window the gns benchmark times (``--sand_block_dir``) is not part
of the repository; this one has its layout and size, not its edges.
"""

import json
import os
import tempfile

import numpy as np

import mpm
from experiments.benchmarks import gns_inputs
from experiments.benchmarks import gns_report
from gnsjax import graph

RADIUS = 0.015  # m
BOUNDS = [[0.1, 0.9], [0.1, 0.9]]  # m


def write_sand_block(directory: str, readme: bool = True) -> int:
  """Writes a window like the shared one to ``directory``.

  1000 sand particles on a 40 x 25 lattice of 0.005 m, jittered by up to
  1 mm (so that no pair sits at exactly R), falling for 7 frames; its
  metadata; and, if ``readme``, a README quoting ``gns_report.PEERS``.

  Returns:
    Directed edges of the last input frame at R, self-pairs included.
  """
  rng = np.random.default_rng(0)
  i, j = np.meshgrid(np.arange(40), np.arange(25), indexing="ij")
  base = np.stack([0.44 + 0.005 * i.ravel(), 0.1025 + 0.005 * j.ravel()], -1)
  base += rng.uniform(-0.001, 0.001, base.shape)
  frames = gns_inputs.INPUT_FRAMES + 1
  fall = -1e-5 * np.arange(frames)**2  # m, as under gravity
  positions = (base[None] + np.stack([np.zeros(frames), fall], -1)[:, None])
  np.savez(os.path.join(directory, gns_inputs.SAND_BLOCK_NPZ),
           positions=positions.astype(np.float32),
           particle_type=np.full(len(base), mpm.SAND_TYPE, np.int32))
  metadata = {"bounds": BOUNDS, "default_connectivity_radius": RADIUS,
              "dim": 2, "dt": 0.0025,
              "vel_mean": [0.0, -1e-4], "vel_std": [1e-4, 1e-4],
              "acc_mean": [0.0, -2e-5], "acc_std": [1e-5, 1e-5]}
  with open(os.path.join(directory, gns_inputs.SAND_BLOCK_METADATA),
            "w") as f:
    json.dump(metadata, f)
  if readme:
    with open(os.path.join(directory, gns_inputs.SAND_BLOCK_README),
              "w") as f:
      f.write("# Shared benchmark input\n\n" + "\n".join(
          f"{peer}: {p['forward_s']:.2f} s per forward step and\n"
          f"{p['train_step_s']:.2f} s per training step."
          for peer, p in gns_report.PEERS.items()) + "\n")
  last = positions[gns_inputs.INPUT_FRAMES - 1]
  return len(graph.brute_force_edges(last.astype(np.float32), RADIUS))


def tempdir(test) -> str:
  """A temporary directory removed after ``test`` (works before absl has
  parsed its flags, unlike ``create_tempdir``)."""
  d = tempfile.TemporaryDirectory()
  test.addCleanup(d.cleanup)
  return d.name
