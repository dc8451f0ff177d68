"""gnsjax: a graph network simulator of granular avalanches, in JAX.

Modules (import them directly; importing ``gnsjax`` loads nothing heavy):

- ``gnsjax.data``: training windows and trajectories from dataset files.
- ``gnsjax.graph``: radius graphs from jax-md neighbour lists.
- ``gnsjax.batching``: padded training batches, on the host or gathered on
  the device (``DeviceWindows``).
- ``gnsjax.features``, ``gnsjax.noise``: model inputs (velocities and the
  scene's signed distance field), targets, training noise.
- ``gnsjax.models``: the encode-process-decode network (Flax + jraph).
- ``gnsjax.simulator``, ``gnsjax.rollout``: one step with the solid
  constraint, and the one rollout engine (``rollout.unroll``) under scan.
- ``gnsjax.train``, ``gnsjax.checkpoint``: training with optax and orbax;
  ``gnsjax.unrolled``, the loss through K learned steps; ``gnsjax.train_eval``,
  the evaluation a run logs.
- ``gnsjax.run``: a trained run's problem, and ``load_run`` for inference.
- ``gnsjax.metrics``: accuracy and flow checks (positional MSE, front,
  deposit, sand inside solids or outside the domain).
- ``gnsjax.design``: inverse design of an obstacle's placement by gradients
  through the GNS or the MPM (a package: placement, objectives, rollouts,
  optimize, smoothing, baselines, calibration's solver, scenes).
- ``gnsjax.config``: a training config's keys and ranges, checked before
  any work.

The studies (the paper's evaluation, stability, the speed/accuracy trade,
inverse design, ...) are ``experiments.studies``; pictures are drawn in
``experiments.figures``; npz datasets of DeepMind's and
geoelements' GNS are read and written by ``mpm.interop``.
"""
