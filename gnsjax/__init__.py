"""gnsjax: a graph network simulator of granular avalanches, in JAX.

Modules (import them directly; importing ``gnsjax`` loads nothing heavy):

- ``gnsjax.data``: training windows and trajectories from dataset files.
- ``gnsjax.graph``: radius graphs from jax-md neighbour lists.
- ``gnsjax.features``, ``gnsjax.noise``: model inputs, targets, training noise.
- ``gnsjax.models``: the encode-process-decode network (Flax + jraph).
- ``gnsjax.simulator``, ``gnsjax.rollout``: one step, and rollouts under scan.
- ``gnsjax.train``, ``gnsjax.checkpoint``: training with optax and orbax.
- ``gnsjax.metrics``, ``gnsjax.evaluate``: the paper's evaluation.
- ``gnsjax.design``: inverse design of an obstacle's placement by gradients
  through the GNS or the MPM (a package: placement, objectives, rollouts,
  optimize, study).

Pictures are drawn in ``experiments.figures``; npz datasets of DeepMind's and
geoelements' GNS are read and written by ``mpm.interop``.
"""
