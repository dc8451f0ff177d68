"""Lone particles sliding on the runout floor: does a learned model stop
them as Coulomb friction would? (docs/gns_log.md, "Training on: longer, or with
a larger batch"; its output is lone_particles.txt.)

  python docs/results/lone_particles.py MODEL [MODEL ...]

Three particles 15 cm apart (out of each other's 3 cm reach) on the floor of
test trajectory 0's scene (no obstacle), started sliding toward -x at v0
for 16 stored frames, then 60 learned steps (0.45 s). Coulomb friction at the
scene's boundary friction mu_b stops a particle at v0 in v0^2 / (2 mu_b g).
"""
import dataclasses
import sys

import jax.numpy as jnp
import numpy as np

from gnsjax import rollout as rollout_lib
from gnsjax import run as run_lib
from mpm import geometry
from mpm import io as mpm_io

INPUT_FRAMES = 16  # (6 - 1) * 3 + 1 stored frames feed the first learned step
STEPS = 60
SPACING = 0.01     # the small config's particle spacing (m)

t0 = next(iter(mpm_io.read_trajectories("data/small1000/test.h5")))
scene = t0.scene
ramp = geometry.ramp_params(scene.ramp)
xs = np.array([0.15, 0.30, 0.45])
floor = np.asarray(geometry.ramp_height(ramp, jnp.asarray(xs)))
print("floor height (m) at x =", xs, ":", np.round(floor, 4), "mu_b",
      scene.boundary_friction)
runs = [run_lib.load_run(w) for w in sys.argv[1:]]
for v0 in (0.1, 0.3, 0.6):
  times = np.arange(INPUT_FRAMES) * scene.frame_dt
  x = xs[None, :] - v0 * times[:, None]
  y = np.broadcast_to(floor + SPACING / 2, x.shape)
  pos = np.stack([x, y], -1).astype(np.float32)
  t = dataclasses.replace(t0, positions=pos, particle_type=None)
  coulomb = v0**2 / (2 * scene.boundary_friction * 9.81)
  for workdir, run in zip(sys.argv[1:], runs):
    out = np.asarray(rollout_lib.rollout_trajectory(
        run.model, run.params, t, run.problem, n_steps=STEPS).positions)
    dt = run.problem.frame_stride * scene.frame_dt
    speed = np.linalg.norm(np.diff(out, axis=0), axis=-1) / dt
    travel = np.abs(out[-1, :, 0] - pos[-1, :, 0])
    print(f"v0 {v0} m/s {workdir.rstrip('/').split('/')[-1]:24s} travel (cm) "
          f"{np.round(100 * travel, 1)}, Coulomb {100 * coulomb:.1f}; speed at "
          f"0.15 s {np.round(100 * speed[19], 1)}, at 0.45 s "
          f"{np.round(100 * speed[-1], 1)} cm/s; height above the floor "
          f"{np.round(100 * (out[-1, :, 1] - floor), 1)} cm (started at 0.5)")
