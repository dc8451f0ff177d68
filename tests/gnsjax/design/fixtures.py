"""A small design scene and an untrained GNS for the inverse-design tests."""

import jax
import numpy as np

import mpm
from gnsjax import features
from gnsjax import graph
from gnsjax import models
from gnsjax import run as run_lib
from gnsjax.design import placement as placement_lib
from gnsjax.design import rollouts

C = 6
# A small heap (spacing 0.01 m, 60 particles) released onto a semicircle:
# the obstacle acts on the sand from the first frames.
X = 1.28
SCENE = {
    "name": "design_test",
    "obstacles": [{"shape": "semicircle", "x": X, "radius": 0.03}],
    "granular": {"box": [1.25, 0.5, 1.46, 1.19], "spacing": 0.01,
                 "num_particles": 60},
}


def scene(**overrides) -> mpm.Scene:
  return mpm.Scene.from_dict({**SCENE, **overrides})


def tiny_gns(placement: placement_lib.Placement, num_frames: int,
             window: np.ndarray | None = None, frame_stride: int = 1,
             boundary: bool = True,
             smooth_cutoff: float = 0.0) -> rollouts.GNSDriver:
  """A GNS driver of an untrained two-step model (random weights); the
  window is the MPM's unless given."""
  model = models.EncodeProcessDecode(latent_size=16, hidden_layers=1,
                                     num_message_passing_steps=2,
                                     type_embedding_size=4,
                                     smooth_cutoff=smooth_cutoff)
  params = models.init_params(model, jax.random.key(0),
                              features.num_node_features(C))
  bounds = ((0.0, 1.65), (0.0, 1.19))
  stats = features.Stats(np.zeros(2, np.float32), np.full(2, 1e-3, np.float32),
                         np.zeros(2, np.float32), np.full(2, 1e-3, np.float32))
  problem = run_lib.Problem(stats, graph.GraphSpec(0.03, bounds),
                            input_frames=C,
                          frame_stride=frame_stride,
                          boundary_particles=boundary, sdf_spacing=0.005)
  if window is None:
    window = rollouts.mpm_window(placement.scene, C, frame_stride)
  sim = rollouts.GNSRollout.create(placement, model, problem, window,
                                   num_frames)
  return rollouts.GNSDriver(sim, params)


# Two semicircles the sand meets within 40 frames: one under the heap, one
# just downstream (base centres 0.05 m apart, the sum of their radii).
TWO_OBSTACLES = [{"shape": "semicircle", "x": X, "radius": 0.03},
                 {"shape": "semicircle", "x": 1.225, "radius": 0.02}]
