"""Tests for unrolled training (`gnsjax.unrolled`, and its use by
`gnsjax.train`): the loss against the one-step loss and against the model
stepped by hand, its gradient, and runs that use it."""

import os

from absl.testing import absltest
import jax
import jax.numpy as jnp
import numpy as np

from gnsjax import batch_kinds
from gnsjax import data
from gnsjax import graph
from gnsjax import rollout
from gnsjax import run as run_lib
from gnsjax import simulator
from gnsjax import train
from gnsjax import unrolled
from mpm import geometry
from tests.gnsjax import fixtures


class UnrolledLossTest(fixtures.TinyRunTestCase):

  K = 2

  def setUp(self):
    super().setUp()
    config = fixtures.tiny_config(unroll_steps=self.K, unroll_probability=1.0)
    self.problem = run_lib.load_problem(self.data, config)
    self.trainer = train.Trainer(config, self.problem)
    self.params = self.trainer.init_state(0).params
    c = self.problem.input_frames
    with data.WindowDataset(data.split_path(self.data, "train"),
                            input_frames=c + self.K - 1, seed=0) as ds:
      self.batch = self.trainer.make_batch([ds[0], ds[3]])
    self.positions = jnp.asarray(self.batch.positions)    # [B, C + K, N, 2]
    start = self.positions.shape[1] - c - self.K
    self.scene = rollout.SceneNodes(
        jnp.swapaxes(self.positions[:, start:start + c], 0, 1),
        jnp.asarray(self.batch.particle_type), jnp.asarray(self.batch.moving),
        geometry.SDFGrid(jnp.asarray(self.batch.solids),
                         self.problem.sdf_spacing))
    self.truth = jnp.swapaxes(self.positions[:, start + c:], 0, 1)
    self.predictor = simulator.ModelPredictor(self.trainer.model)

  def _loss(self, truth, project, params=None):
    nbrs = graph.allocate_batch(self.problem.spec, self.scene.window[-1])
    scene = self.scene
    if truth.shape[0] < self.K:  # start K - 1 frames later
      c = self.problem.input_frames
      scene = scene._replace(window=jnp.swapaxes(
          self.positions[:, -c - 1:-1], 0, 1))
    loss, overflow = unrolled.unrolled_loss(
        self.predictor, self.params if params is None else params, scene,
        truth, nbrs, self.problem.context, self.problem.spec, project)
    self.assertFalse(bool(overflow))
    return float(loss)

  def test_one_step_is_the_one_step_loss(self):
    graphs, target = self.trainer.batch_arrays(self.batch, None, noise=False)
    want = float(self.trainer.eval_loss(self.params, graphs, target))
    got = self._loss(self.positions[:, -1][None], project=False)
    np.testing.assert_allclose(got, want, rtol=1e-4)  # float32 sums

  def test_two_steps_equal_the_model_stepped_by_hand(self):
    # Each window stepped twice by simulator.step (with the constraint and a
    # fresh graph each step), the error of each step scaled by the
    # acceleration std, averaged over steps, moving nodes and windows.
    ctx, spec = self.problem.context, self.problem.spec
    std = np.asarray(ctx.stats.acc_std)
    per_window = []
    for b in range(self.positions.shape[0]):
      window = self.scene.window[:, b]
      moving = self.scene.moving[b]
      solids = geometry.SDFGrid(self.scene.solids.values[b],
                                self.scene.solids.spacing)
      total = 0.0
      for k in range(self.K):
        nbrs = graph.allocate(spec, window[-1])
        senders, receivers = graph.edges(nbrs, window.shape[1])
        g = simulator.Graph(window, self.scene.types[b], moving, senders,
                            receivers, solids)
        nxt, last, _ = simulator.step(self.predictor, self.params, g, ctx,
                                      spec.radius, project=True)
        window = jnp.concatenate([window[1:-1], last[None], nxt[None]], 0)
        err = np.sum(((np.asarray(nxt) - np.asarray(self.truth[k, b])) /
                      std)**2, -1)
        total += np.sum(err * np.asarray(moving)) / np.sum(moving) / 2
      per_window.append(total / self.K)
    got = self._loss(self.truth, project=True)
    np.testing.assert_allclose(got, np.mean(per_window), rtol=1e-4)

  def test_training_on_one_batch_lowers_its_loss(self):
    # Steps on the same batch and key (so the same noisy inputs): the
    # gradient through both steps lowers the two-step loss at every step
    # (an untrained model's loss is large; clipped Adam steps are small).
    state = self.trainer.init_state(0)
    key = jax.random.key(1)
    losses = []
    for _ in range(10):
      state, metrics = self.trainer.train_unrolled(state, self.batch, key,
                                                   self.K)
      losses.append(float(metrics["loss"]))
    self.assertTrue(np.all(np.isfinite(losses)))
    self.assertTrue(np.all(np.diff(losses) < 0), losses)
    self.assertLess(losses[-1], 0.99 * losses[0])
    self.assertEqual(int(state.step), 10)


class BatchKindTest(absltest.TestCase):
  """`batch_kinds.choose`: which of unrolled, pushforward and rest
  pushforward a batch gets, against the draws that define it."""

  def _config(self, moving_only):
    config = fixtures.tiny_config(
        unroll_steps=4, unroll_probability=0.5, pushforward_steps=3,
        pushforward_probability=0.5, rest_pushforward_steps=40,
        rest_pushforward_probability=0.7, unroll_moving_only=moving_only)
    return config.train

  def _draw(self, step, stream):
    return np.random.default_rng([0, step, stream]).random()

  def test_moving_only_gives_still_batches_to_the_rest_pushforward(self):
    for moving_only in (False, True):
      tcfg = self._config(moving_only)
      for still in (False, True):
        for step in range(40):
          kind = batch_kinds.choose(tcfg, step, 4, 3, lambda: still)
          self.assertLessEqual(sum(k > 0 for k in kind), 1)
          unrolled = (self._draw(step, 3) < 0.5 and
                      not (moving_only and still))
          push = not unrolled and self._draw(step, 1) < 0.5
          rest = (not unrolled and not push and still and
                  self._draw(step, 2) < 0.7)
          self.assertEqual(kind, (4 * unrolled, 3 * push, 40 * rest),
                           (moving_only, still, step))

  def test_the_batch_is_looked_at_once_and_only_when_needed(self):
    calls = []
    def any_still():
      calls.append(1)
      return True
    tcfg = self._config(True)
    for step in range(40):
      calls.clear()
      kind = batch_kinds.choose(tcfg, step, 4, 3, any_still)
      self.assertLessEqual(len(calls), 1)
      if self._draw(step, 3) >= 0.5 and self._draw(step, 1) < 0.5:
        # pushed forward, not unrolled: stillness is not asked
        self.assertEqual((kind, calls), ((0, 3, 0), []))


class UnrolledRunTest(fixtures.TinyRunTestCase):

  def _run(self, name, num_steps, **options):
    config = fixtures.tiny_config(num_steps=num_steps, **options)
    config.log_every = 1
    workdir = os.path.join(self.dir, name)
    train.train_and_evaluate(config, self.data, workdir)
    return fixtures.logged_losses(workdir)

  def test_probability_zero_changes_nothing(self):
    plain = self._run("plain", 3)
    off = self._run("off", 3, unroll_steps=3, unroll_probability=0.0)
    self.assertEqual(sorted(off), [1, 2, 3])
    for step in off:
      np.testing.assert_allclose(off[step], plain[step], rtol=1e-6)

  def test_mixed_run_resumes_as_uninterrupted(self):
    # Unrolled, pushforward and one-step batches mixed; a run stopped at
    # step 4 (its checkpoint) and resumed logs the losses of one that
    # never stopped.
    options = dict(unroll_steps=3, unroll_probability=0.4,
                   pushforward_steps=2, pushforward_probability=0.5)
    unrolled_steps = [s for s in range(6) if np.random.default_rng(
        [0, s, 3]).random() < 0.4]  # the run's draw (seed 0)
    self.assertTrue(any(s < 4 for s in unrolled_steps) and
                    any(s >= 4 for s in unrolled_steps))
    full = self._run("full", 6, **options)
    self._run("split", 4, **options)
    split = self._run("split", 6, **options)
    self.assertEqual(sorted(split), list(range(1, 7)))
    for step in range(1, 7):
      np.testing.assert_allclose(split[step], full[step], rtol=1e-5)

if __name__ == "__main__":
  absltest.main()
