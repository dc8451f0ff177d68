"""Random-walk noise on input positions (Sanchez-Gonzalez et al. 2020).

Training adds noise to the input velocities so the model learns to correct
the errors it will make in its own rollouts. The velocity noise is a random
walk over the C - 1 input velocities whose last step has standard deviation
``noise_std`` (m/frame); positions get its running sum. The target is moved
with the last input position, so the model is asked to undo the velocity
noise (``adjust_target``).
"""

import jax
import jax.numpy as jnp


def random_walk(key: jax.Array, shape: tuple[int, int, int],
                noise_std: float) -> jax.Array:
  """Position noise [C, N, 2] for C input frames.

  Each of the C - 1 velocity increments has std noise_std / sqrt(C - 1), so
  the walk's last velocity has std ``noise_std``; frame 0 is not perturbed.
  """
  steps = shape[0] - 1
  increments = jax.random.normal(key, (steps,) + tuple(shape[1:])) * (
      noise_std / jnp.sqrt(steps))
  velocity_noise = jnp.cumsum(increments, axis=0)
  return jnp.concatenate([jnp.zeros((1,) + tuple(shape[1:])),
                          jnp.cumsum(velocity_noise, axis=0)])


def adjust_target(target: jax.Array, noise: jax.Array) -> jax.Array:
  """Target [N, 2] shifted with the last input frame's noise [C, N, 2]."""
  return target + noise[-1]
