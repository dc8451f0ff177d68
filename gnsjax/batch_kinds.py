"""Which loss each training batch gets: one-step (the default), unrolled
through K learned steps (``gnsjax.unrolled``), pushforward (P learned
steps without gradient, then one with), or rest pushforward (the same,
longer, on batches that hold a still window).

``choose`` is a pure function of the config and the step: each kind is
drawn from (``train.seed``, step, its own stream), so a resumed run makes
the same choices as an uninterrupted one. Looking at the batch (whether it
holds a still window, ``any_still``) costs a device round trip, so it is
asked lazily, at most once, and only when the choice depends on it.
"""

import functools
from typing import Callable

import numpy as np

from gnsjax import batching
from gnsjax import distributed
from gnsjax import noise as noise_lib

# The random streams of the three draws, fixed so that runs stay comparable.
_PUSHFORWARD, _REST, _UNROLL = 1, 2, 3


def any_still(batch: batching.Batch, tcfg) -> bool:
  """Whether any window of ``batch`` is still (``noise.still`` at
  ``train.rest_pushforward_speed``), on every process."""
  return distributed.agree_any(np.any(noise_lib.still(
      batch.positions, batch.moving, tcfg.frame_stride,
      tcfg.rest_pushforward_speed)))


def choose(tcfg, step: int, unroll: int, pushforward: int,
           batch_is_still: Callable[[], bool]) -> tuple[int, int, int]:
  """(unrolled steps, pushforward steps, rest pushforward steps) of the
  batch at ``step``, at most one of them nonzero.

  Args:
    tcfg: the ``train`` section (seed, the kinds' probabilities and
      ``unroll_moving_only``, ``rest_pushforward_steps``).
    step: the training step.
    unroll, pushforward: the unrolled and pushforward step counts in force
      at this step (0: that kind is off).
    batch_is_still: () -> whether the batch holds a still window; called
      at most once, and only when the choice depends on it.
  """
  still = functools.cache(batch_is_still)
  draw = lambda stream: np.random.default_rng(
      [tcfg.seed, step, stream]).random()
  unrolled = unroll if unroll and draw(_UNROLL) < tcfg.unroll_probability \
      else 0
  if unrolled and tcfg.unroll_moving_only and still():
    unrolled = 0
  push = pushforward if pushforward and not unrolled and (
      draw(_PUSHFORWARD) < tcfg.pushforward_probability) else 0
  rest = tcfg.rest_pushforward_steps if (
      not push and not unrolled and tcfg.rest_pushforward_steps and
      draw(_REST) < tcfg.rest_pushforward_probability and still()) else 0
  return unrolled, push, rest
