"""Tests for the training windows of `gnsjax.train`: what each batch's
inputs and targets are under pushforward, noisy targets kept out of solids,
clean or quiet resting windows and their weights, and the rest pushforward.
"""

import os

from absl.testing import absltest
import jax
import jax.numpy as jnp
import numpy as np

from gnsjax import data
from gnsjax import noise
from gnsjax import rollout
from gnsjax import run as run_lib
from gnsjax import simulator
from gnsjax import train
from mpm import geometry
from tests.gnsjax import fixtures


class PushforwardTest(fixtures.TinyRunTestCase):

  P = 2

  def _pushforward_batch(self, **options):
    """(problem, trainer, initial state, a batch of two windows of C + P
    + 1 frames) of a tiny run that always pushes forward P steps."""
    config = fixtures.tiny_config(pushforward_steps=self.P,
                                  pushforward_probability=1.0, **options)
    problem = run_lib.load_problem(self.data, config)
    trainer = train.Trainer(config, problem)
    with data.WindowDataset(data.split_path(self.data, "train"),
                            input_frames=problem.input_frames + self.P,
                            seed=0) as ds:
      batch = trainer.make_batch([ds[0], ds[1]])
    return problem, trainer, trainer.init_state(0), batch

  def _noisy_start(self, problem, trainer, batch, key):
    """The noisy first C frames [B, C, N, 2] that ``batch_arrays`` draws
    with ``key`` and pushes forward."""
    c = problem.input_frames
    solids = geometry.SDFGrid(trainer.put(batch.solids), problem.sdf_spacing)
    start, _ = trainer.prepare(key, trainer.put(batch.positions[:, :c + 1]),
                               trainer.put(batch.moving), solids)
    return np.asarray(start)

  def test_probability_zero_changes_nothing(self):
    losses = {}
    for steps in (0, self.P):
      config = fixtures.tiny_config(num_steps=3, pushforward_steps=steps,
                                    pushforward_probability=0.0)
      config.log_every = 1
      workdir = os.path.join(self.dir, str(steps))
      train.train_and_evaluate(config, self.data, workdir)
      losses[steps] = fixtures.logged_losses(workdir)
    self.assertEqual(sorted(losses[0]), [1, 2, 3])
    for step in (1, 2, 3):
      np.testing.assert_allclose(losses[self.P][step], losses[0][step],
                                 rtol=1e-6, err_msg=f"step {step}")

  def test_inputs_are_the_models_own_rollout(self):
    p = self.P
    problem, trainer, state, batch = self._pushforward_batch()
    c = problem.input_frames
    self.assertEqual(batch.positions.shape[1], c + p + 1)
    graphs, target = trainer.batch_arrays(batch, None, noise=False,
                                          params=state.params, pushforward=p)
    inputs, target = np.asarray(graphs.positions), np.asarray(target)
    moving = batch.moving
    # The target is the true frame P steps after the first C.
    np.testing.assert_array_equal(target, batch.positions[:, c + p])
    # The inputs: the true frames P to C - 2, then what a rollout of the
    # model from the first C frames carries after P steps.
    np.testing.assert_array_equal(inputs[:, :c - p - 1],
                                  batch.positions[:, p:c - 1])
    self.assertGreater(np.max(np.abs(inputs[:, -1][moving] -
                                     batch.positions[:, c + p - 1][moving])),
                       1e-7)
    for b in range(len(inputs)):
      scene = rollout.SceneNodes(
          batch.positions[b, :c], batch.particle_type[b], moving[b],
          geometry.SDFGrid(batch.solids[b], problem.sdf_spacing))
      own = rollout.rollout(simulator.ModelPredictor(trainer.model),
                            state.params, scene, p, problem.context,
                            problem.spec)
      np.testing.assert_allclose(inputs[b, -1], own.positions[-1], atol=1e-6)
      np.testing.assert_allclose(inputs[b, -2][moving[b]],
                                 own.positions[-2][moving[b]], atol=1e-5)
    # Without pushforward the same batch gives its last C + 1 frames.
    graphs, target = trainer.batch_arrays(batch, None, noise=False)
    np.testing.assert_array_equal(graphs.positions, batch.positions[:, p:-1])
    np.testing.assert_array_equal(target, batch.positions[:, -1])

  def test_the_unconstrained_unroll_is_the_rollout_without_projection(self):
    # Off, the model's own steps into a solid stay in its inputs, so it
    # learns to leave a solid rather than lean on the constraint.
    p = self.P
    key = jax.random.key(3)
    for constrained in (True, False):
      # Noise of 3 mm per step: sand near the ramp starts inside it.
      problem, trainer, state, batch = self._pushforward_batch(
          noise_std=3e-3, pushforward_constrained=constrained)
      graphs, _ = trainer.batch_arrays(batch, key, params=state.params,
                                       pushforward=p)
      last = np.asarray(graphs.positions[:, -1])
      start = self._noisy_start(problem, trainer, batch, key)
      inside = 0
      for b in range(len(batch.moving)):
        solids = geometry.SDFGrid(jnp.asarray(batch.solids[b]),
                                  problem.sdf_spacing)
        scene = rollout.SceneNodes(start[b], batch.particle_type[b],
                                   batch.moving[b], solids)
        own = rollout.rollout(simulator.ModelPredictor(trainer.model),
                              state.params, scene, p, problem.context,
                              problem.spec, project=constrained)
        np.testing.assert_allclose(last[b], own.positions[-1], atol=1e-6,
                                   err_msg=f"constrained={constrained}")
        sdf, _ = geometry.sample_sdf(solids, jnp.asarray(last[b]))
        inside += np.sum(batch.moving[b] & (np.asarray(sdf) < -1e-5))
      if constrained:
        self.assertEqual(inside, 0)
      else:
        self.assertGreater(inside, 0)

  def test_a_noisy_start_moves_the_target_with_its_noise(self):
    # The noise shifts the start's positions; the model learns to keep that
    # shift, so the true frame P steps on is moved by it too (LagrangeBench).
    p = self.P
    problem, trainer, state, batch = self._pushforward_batch(noise_std=1e-3)
    c = problem.input_frames
    key = jax.random.key(3)
    _, target = trainer.batch_arrays(batch, key, params=state.params,
                                     pushforward=p)
    start = self._noisy_start(problem, trainer, batch, key)
    offset = start[:, -1] - batch.positions[:, c - 1]
    self.assertGreater(np.max(np.abs(offset)), 5e-4)
    np.testing.assert_allclose(target, batch.positions[:, c + p] + offset,
                               atol=1e-6)


class TargetOutsideSolidsTest(fixtures.TinyRunTestCase):

  def test_the_flag_pushes_noisy_targets_out_and_changes_nothing_else(self):
    out = {}
    for flag in (False, True):
      # Noise of 3 mm per step: sand near the ramp ends up inside it.
      config = fixtures.tiny_config(noise_std=3e-3,
                                    target_outside_solids=flag)
      problem = run_lib.load_problem(self.data, config)
      trainer = train.Trainer(config, problem)
      with data.WindowDataset(data.split_path(self.data, "train"),
                              input_frames=problem.input_frames,
                              seed=0) as ds:
        batch = trainer.make_batch([ds[0], ds[1]])
      graphs, target = trainer.batch_arrays(batch, jax.random.key(3))
      out[flag] = np.asarray(graphs.positions), np.asarray(target)
    np.testing.assert_array_equal(out[True][0], out[False][0])
    inside = np.zeros(batch.moving.shape, bool)
    for b in range(len(inside)):
      solids = geometry.SDFGrid(jnp.asarray(batch.solids[b]),
                                problem.sdf_spacing)
      before, _ = geometry.sample_sdf(solids, jnp.asarray(out[False][1][b]))
      after, _ = geometry.sample_sdf(solids, jnp.asarray(out[True][1][b]))
      inside[b] = batch.moving[b] & (np.asarray(before) < 0)
      np.testing.assert_array_less(-1e-5, np.asarray(after)[batch.moving[b]])
    self.assertGreater(inside.sum(), 0)
    np.testing.assert_array_equal(out[True][1][~inside],
                                  out[False][1][~inside])



class RestingTest(absltest.TestCase):

  def test_resting_is_the_sands_mean_speed_below_the_bound(self):
    c, n, stride = 6, 4, 3
    still = np.zeros((c, n, 2), np.float32)
    # The sand creeps at 0.9x and 1.1x the bound per stored frame; the
    # padding node (not moving) flies, which must not count.
    slow, fast = (np.zeros((c, n, 2), np.float32) for _ in range(2))
    for w, factor in ((slow, 0.9), (fast, 1.1)):
      w[:, :3, 0] = np.arange(c)[:, None] * stride * factor * (
          noise.RESTING_SPEED)
    for w in (still, slow, fast):
      w[:, 3, 1] = np.arange(c) * 1.0
    moving = np.array([[True, True, True, False]] * 3)
    got = noise.resting(jnp.asarray(np.stack([still, slow, fast])),
                        jnp.asarray(moving), stride)
    np.testing.assert_array_equal(got, [True, True, False])


def _trainer_and_batch(data_dir, **options):
  """A trainer (3 mm noise, ``options`` on the tiny config's train section)
  and a batch of eight tiny windows; the sand of windows 2 and 5 is held
  still at its first frame (the tiny data's sand always moves)."""
  config = fixtures.tiny_config(noise_std=3e-3, **options)
  trainer = train.Trainer(config, run_lib.load_problem(data_dir, config))
  with data.WindowDataset(data.split_path(data_dir, "train"),
                          input_frames=trainer.problem.input_frames,
                          seed=0) as ds:
    windows = [ds[k] for k in range(8)]
  for k in (2, 5):
    x = windows[k].positions
    windows[k] = windows[k]._replace(
        positions=np.broadcast_to(x[:1], x.shape).copy())
  return trainer, trainer.make_batch(windows)


class CleanFractionTest(fixtures.TinyRunTestCase):

  def _batch_arrays(self, **options):
    """(batch, (inputs, targets)) of ``_trainer_and_batch``'s windows."""
    trainer, batch = _trainer_and_batch(self.data, **options)
    graphs, target = trainer.batch_arrays(batch, jax.random.key(3))
    return batch, (np.asarray(graphs.positions), np.asarray(target))

  def test_a_window_is_either_clean_or_noised_as_without_the_option(self):
    out = {}
    for fraction in (0.0, 0.5, 1.0):
      batch, out[fraction] = self._batch_arrays(clean_fraction=fraction)
    c = out[0.0][0].shape[1]
    clean = batch.positions[:, -c - 1:-1], batch.positions[:, -1]
    # All clean: the true frames, the true next frame.
    np.testing.assert_array_equal(out[1.0][0], clean[0])
    np.testing.assert_array_equal(out[1.0][1], clean[1])
    self.assertGreater(np.abs(out[0.0][0] - clean[0]).max(), 1e-4)
    # Half: each window is the clean one or the one without the option
    # (the same noise), and both kinds occur.
    kinds = []
    for b in range(len(batch.positions)):
      same_as = [np.array_equal(out[0.5][0][b], ref[0][b]) and
                 np.array_equal(out[0.5][1][b], ref[1][b])
                 for ref in (clean, out[0.0])]
      self.assertEqual(sum(same_as), 1, f"window {b}")
      kinds.append(same_as[0])
    self.assertIn(True, kinds)
    self.assertIn(False, kinds)

  def test_quiet_windows_get_the_same_noise_scaled_down(self):
    batch, (noisy, _) = self._batch_arrays(clean_fraction=0.0)
    _, (quiet, _) = self._batch_arrays(clean_fraction=1.0,
                                       clean_scale_min=0.01)
    c = noisy.shape[1]
    clean = batch.positions[:, -c - 1:-1]
    moved = np.abs(noisy - clean) > 1e-3   # well above float32 rounding
    ratio = (quiet - clean)[moved] / (noisy - clean)[moved]
    scales = []
    for b in range(len(batch.positions)):
      per_window = ratio[np.nonzero(moved)[0] == b]
      np.testing.assert_allclose(per_window, per_window[0], rtol=3e-2)
      scales.append(per_window[0])
    self.assertTrue(all(0.01 <= s <= 1.0 + 1e-3 for s in scales), scales)
    self.assertGreater(max(scales) / min(scales), 2.0)

  def test_only_resting_windows_are_left_clean_with_the_option(self):
    batch, noisy = self._batch_arrays(clean_fraction=0.0)
    _, out = self._batch_arrays(clean_fraction=1.0, clean_resting_only=True)
    c = noisy[0].shape[1]
    inputs = batch.positions[:, -c - 1:-1]
    rest = np.asarray(noise.resting(jnp.asarray(inputs),
                                    jnp.asarray(batch.moving),
                                    fixtures.tiny_config().train.frame_stride))
    np.testing.assert_array_equal(rest, np.isin(np.arange(8), (2, 5)))
    for b in range(len(rest)):
      want = ((inputs[b], batch.positions[b, -1]) if rest[b] else
              (noisy[0][b], noisy[1][b]))
      np.testing.assert_array_equal(out[0][b], want[0])
      np.testing.assert_array_equal(out[1][b], want[1])


class RestPushforwardTest(fixtures.TinyRunTestCase):

  R = 4

  def test_still_windows_start_from_the_models_own_frames(self):
    # Windows 2 and 5 are still: their inputs are the model's frames R
    # steps on from their true inputs, their target the true (resting)
    # next frame. The moving windows are as without the option.
    trainer, batch = _trainer_and_batch(
        self.data, rest_pushforward_steps=self.R,
        rest_pushforward_probability=1.0)
    params = trainer.init_state(0).params
    plain, plain_target = trainer.batch_arrays(batch, None, noise=False)
    graphs, target = trainer.batch_arrays(batch, None, noise=False,
                                          params=params,
                                          rest_pushforward=self.R)
    inputs, plain = np.asarray(graphs.positions), np.asarray(plain.positions)
    np.testing.assert_array_equal(target, plain_target)
    stride = trainer.config.train.frame_stride
    still = np.asarray(noise.still(batch.positions, batch.moving, stride))
    np.testing.assert_array_equal(still, np.isin(np.arange(8), (2, 5)))
    problem = trainer.problem
    for b in range(len(still)):
      if not still[b]:
        np.testing.assert_array_equal(inputs[b], plain[b])
        continue
      scene = rollout.SceneNodes(
          plain[b], batch.particle_type[b], batch.moving[b],
          geometry.SDFGrid(batch.solids[b], problem.sdf_spacing))
      own = rollout.rollout(simulator.ModelPredictor(trainer.model), params,
                            scene, self.R, problem.context, problem.spec)
      np.testing.assert_allclose(inputs[b, -1], own.positions[-1],
                                 atol=1e-6)
      moving = batch.moving[b]
      # An untrained model moves the still sand.
      self.assertGreater(np.abs(inputs[b, -1][moving] -
                                plain[b, -1][moving]).max(), 1e-6)

  def test_the_stay_target_moves_with_the_models_drift(self):
    # Every window counted still: the target is the true next frame moved
    # by how far the model's R steps took the last input frame, pushed out
    # of the solids as a noisy target is.
    trainer, batch = _trainer_and_batch(
        self.data, rest_pushforward_steps=self.R,
        rest_pushforward_probability=1.0, rest_pushforward_speed=1.0,
        rest_pushforward_stay=True)
    params = trainer.init_state(0).params
    plain, plain_target = trainer.batch_arrays(batch, None, noise=False)
    graphs, target = trainer.batch_arrays(batch, None, noise=False,
                                          params=params,
                                          rest_pushforward=self.R)
    drift = graphs.positions[:, -1] - plain.positions[:, -1]
    self.assertGreater(float(jnp.max(jnp.abs(drift))), 1e-6)
    for b in range(len(target)):
      solids = geometry.SDFGrid(batch.solids[b], trainer.problem.sdf_spacing)
      want = simulator.shift_target(plain_target[b], drift[b],
                                    batch.moving[b], solids)
      np.testing.assert_allclose(target[b], want, atol=1e-6)

  def test_training_pushes_only_batches_with_still_sand(self):
    # The tiny data's sand always moves: no batch is pushed, the run is
    # the one without the option; with every window counted still, each
    # batch is pushed and the losses change.
    losses = {}
    for name, steps, bound in (("off", 0, noise.STILL_SPEED),
                               ("moving", self.R, noise.STILL_SPEED),
                               ("still", self.R, 1.0)):
      config = fixtures.tiny_config(num_steps=2, rest_pushforward_steps=steps,
                                    rest_pushforward_probability=1.0,
                                    rest_pushforward_speed=bound)
      config.log_every = 1
      workdir = os.path.join(self.dir, name)
      train.train_and_evaluate(config, self.data, workdir)
      losses[name] = fixtures.logged_losses(workdir)
    self.assertEqual(losses["moving"], losses["off"])
    self.assertNotEqual(losses["still"][1], losses["off"][1])


class CleanWeightTest(fixtures.TinyRunTestCase):

  def test_the_weight_falls_on_exactly_the_windows_left_clean(self):
    key = jax.random.key(3)
    trainer, batch = _trainer_and_batch(self.data, clean_fraction=1.0,
                                        clean_resting_only=True,
                                        clean_weight=10.0)
    np.testing.assert_array_equal(trainer.window_weights(batch, key),
                                  np.where(np.isin(np.arange(8), (2, 5)),
                                           10.0, 1.0))
    # Drawn at random: the same draw as batch_arrays' noise.
    trainer, batch = _trainer_and_batch(self.data, clean_fraction=0.5,
                                        clean_weight=4.0)
    weights = np.asarray(trainer.window_weights(batch, key))
    graphs, _ = trainer.batch_arrays(batch, key)
    c = trainer.problem.input_frames
    clean = np.all(np.asarray(graphs.positions) ==
                   batch.positions[:, -c - 1:-1], axis=(1, 2, 3))
    self.assertTrue(clean.any() and not clean.all())
    np.testing.assert_array_equal(weights, np.where(clean, 4.0, 1.0))
    # Without a weight (or without clean windows) all weigh the same.
    for options in ({"clean_fraction": 0.5}, {"clean_weight": 4.0}):
      trainer, batch = _trainer_and_batch(self.data, **options)
      self.assertIsNone(trainer.window_weights(batch, key))

  def test_the_loss_weighs_each_window_by_its_weight(self):
    trainer, batch = _trainer_and_batch(self.data)
    graphs, target = trainer.batch_arrays(batch, jax.random.key(3))
    params = trainer.init_state(0).params
    b = target.shape[0]
    alone = [float(trainer.eval_loss(params, graphs, target,
                                     b * jnp.eye(b)[k])) for k in range(b)]
    np.testing.assert_allclose(
        float(trainer.eval_loss(params, graphs, target)), np.mean(alone),
        rtol=1e-5)
    weights = jnp.arange(1.0, b + 1)
    np.testing.assert_allclose(
        float(trainer.eval_loss(params, graphs, target, weights)),
        np.mean(np.asarray(weights) * np.array(alone)), rtol=1e-5)


if __name__ == "__main__":
  absltest.main()
