"""gnsjax: a graph network simulator of granular avalanches, in JAX.

Modules (import them directly; importing ``gnsjax`` loads nothing heavy):

- ``gnsjax.data``: training windows and trajectories from dataset files.
- ``gnsjax.graph``: radius graphs from jax-md neighbour lists.
- ``gnsjax.features``, ``gnsjax.noise``: model inputs, targets, training noise.
- ``gnsjax.models``: the encode-process-decode network (Flax + jraph).
- ``gnsjax.simulator``, ``gnsjax.rollout``: one step, and rollouts under scan.
- ``gnsjax.train``, ``gnsjax.checkpoint``: training with optax and orbax.
- ``gnsjax.metrics``, ``gnsjax.evaluate``: the paper's evaluation.
- ``gnsjax.render``: animations and frame grids.
- ``gnsjax.interop``: npz datasets of DeepMind's and geoelements' GNS.
"""
