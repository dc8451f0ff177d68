"""Random-walk noise on input positions (Sanchez-Gonzalez et al. 2020).

Training adds noise to the input velocities so the model learns to correct
the errors it will make in its own rollouts. The velocity noise is a random
walk over the C - 1 input velocities whose last step has standard deviation
``noise_std`` (m/frame); positions get its running sum. The target is moved
with the last input position, so the model is asked to undo the velocity
noise (``gnsjax.simulator.shift_target``). Some windows may be left clean
(``clean_windows``): sand exactly at rest, with its exact zero target,
which noisy windows never show; or quiet, with noise of every amplitude
down to the rollout's jitter at rest (``quiet_scale``; docs/gns.md).
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


# A window's sand rests below this mean speed (m per stored frame): 0.1 mm,
# about 4 cm/s; 38% of the small dataset's windows (docs/gns.md).
RESTING_SPEED = 1e-4
# ... and is still below this one: 2 um, 0.8 mm/s, slow enough that its
# last frame stands for the truth many learned steps later (the default
# train.rest_pushforward_speed). No window of the 1.5 s small dataset is
# that slow (its resting sand settles at 2-4 mm/s); 4.7% of 3 s ones are.
STILL_SPEED = 2e-6


def resting(inputs: jax.Array, moving: jax.Array, stride: int,
            below: float = RESTING_SPEED) -> jax.Array:
  """bool [B]: whether each window's sand rests, its mean speed over the
  input frames [B, C, N, 2] (``stride`` stored frames apart) below
  ``below`` (m per stored frame); ``moving`` [B, N] marks the sand."""
  step = jnp.linalg.norm(jnp.diff(inputs, axis=1), axis=-1)    # [B, C-1, N]
  per_node = jnp.mean(step, axis=1) * moving
  speed = jnp.sum(per_node, -1) / jnp.maximum(jnp.sum(moving, -1), 1)
  return speed / stride < below


def still(positions: jax.Array, moving: jax.Array, stride: int,
          below: float = STILL_SPEED) -> jax.Array:
  """bool [B]: the windows (frames [B, T, N, 2]) whose sand is still over
  all their frames: mean speed below ``below`` (m per stored frame)."""
  return resting(positions, moving, stride, below=below)


def clean_windows(key: jax.Array, positions: jax.Array, moving: jax.Array,
                  fraction: float, resting_only: bool,
                  stride: int) -> jax.Array:
  """bool [B]: the windows (frames [B, C + 1, N, 2], the last the target)
  left without noise: each with probability ``fraction`` (a draw from
  ``fold_in(key, 1)``), and only resting ones if ``resting_only``."""
  eligible = jax.random.uniform(jax.random.fold_in(key, 1),
                                positions.shape[:1]) < fraction
  if resting_only:
    eligible &= resting(positions[:, :-1], moving, stride)
  return eligible


def quiet_scale(key: jax.Array, shape: tuple[int, ...],
                minimum: float) -> jax.Array:
  """Factors on the noise std of the windows left clean, [shape]: 0 if
  ``minimum`` is 0 (exactly clean), else log-uniform in [minimum, 1], so
  that every decade of amplitude is drawn as often."""
  if not minimum:
    return jnp.zeros(shape)
  return minimum ** jax.random.uniform(key, shape)
