"""The compiled chunk programs of ``mpm.simulate_setups``, and their cache.

A run compiles one program per grid, window size, substep count and batch
shape (``chunk_program``); ``compiled`` keeps them for the next run of the
same shapes.
"""

import time

import jax

from mpm import solver

_rollout = jax.jit(solver.rollout, static_argnames=(
    "spec", "n_frames", "n_substeps", "remat"))
_batched_rollout = jax.jit(
    jax.vmap(solver.rollout, in_axes=(0, 0, 0, None, None, None)),
    static_argnums=(3, 4, 5))
_windowed_rollout = jax.jit(solver.rollout_windowed, static_argnames=(
    "spec", "size", "n_frames", "n_substeps", "capacity"))
_batched_windowed_rollout = jax.jit(
    jax.vmap(solver.rollout_windowed, in_axes=(0, 0, 0, None, None, None,
                                               None, None)),
    static_argnums=(3, 4, 5, 6, 7))

# Compiled programs by (function, static args, argument shapes). Each
# program jax keeps holds memory maps, which XLA:CPU runs out of after
# hundreds (the speed/accuracy study crashed so, 2026-11-26), and jax's
# caches keep ours too: past MAX_COMPILED all are dropped
# (``jax.clear_caches``; the entry points' persistent compilation cache
# makes a recompile a read from disk).
_compiled: dict = {}
MAX_COMPILED = 64


def chunk_program(batched: bool, windowed: bool):
  """The jitted rollout of a chunk: ``solver.rollout`` or
  ``solver.rollout_windowed``, vmapped over scenes when ``batched``. Its
  arguments: (state, params, field, spec, [size,] n_frames, n_substeps
  [, capacity])."""
  if windowed:
    return _batched_windowed_rollout if batched else _windowed_rollout
  return _batched_rollout if batched else _rollout


def compiled(fn, *args):
  """(``fn`` compiled for ``args``, seconds spent compiling: 0 when it was
  already). ``args[:3]`` are traced, the rest static."""
  key = (id(fn), args[3:], jax.tree.structure(args[:3]),
         tuple((a.shape, a.dtype) for a in jax.tree.leaves(args[:3])))
  if key in _compiled:
    return _compiled[key], 0.0
  if len(_compiled) >= MAX_COMPILED:
    _compiled.clear()
    jax.clear_caches()
  start = time.perf_counter()
  program = fn.lower(*args).compile()
  _compiled[key] = program
  return program, time.perf_counter() - start
