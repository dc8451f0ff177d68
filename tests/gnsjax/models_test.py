"""Tests for `gnsjax.models`, `gnsjax.features` and `gnsjax.noise`."""

from absl.testing import absltest
from absl.testing import parameterized
import jax
import jax.numpy as jnp
import numpy as np

from gnsjax import features
from gnsjax import models
from gnsjax import noise
from gnsjax import simulator
from mpm import geometry

N, E = 40, 200


def _inputs(seed=0, n=N, e=E):
  rng = np.random.default_rng(seed)
  return (jnp.asarray(rng.normal(size=(n, features.num_node_features(6))),
                      jnp.float32),
          jnp.asarray(rng.integers(0, 9, n), jnp.int32),
          jnp.asarray(rng.normal(size=(e, 3)), jnp.float32),
          jnp.asarray(rng.integers(0, n, e), jnp.int32),
          jnp.asarray(rng.integers(0, n, e), jnp.int32))


def _tiny(split=True):
  return models.EncodeProcessDecode(latent_size=16, hidden_layers=2,
                                    num_message_passing_steps=2,
                                    type_embedding_size=4,
                                    split_first_layer=split)


class ModelTest(parameterized.TestCase):

  def test_split_first_layer_equals_concatenated(self):
    args = _inputs()
    split, concat = _tiny(True), _tiny(False)
    params = split.init(jax.random.key(0), *args)
    mapped = {"params": dict(params["params"])}
    for name in mapped["params"]:
      if name.startswith("step_"):
        mapped["params"][name] = models.split_to_concat_params(
            params["params"][name])
    # The mapped tree has exactly the concatenated model's structure.
    self.assertEqual(
        jax.tree.structure(concat.init(jax.random.key(1), *args)),
        jax.tree.structure(mapped))
    np.testing.assert_allclose(split.apply(params, *args),
                               concat.apply(mapped, *args), atol=1e-5)

  def test_flop_count_matches_xla(self):
    args = _inputs(n=300, e=3000)
    measured = {}
    for split in (True, False):
      m = models.EncodeProcessDecode(latent_size=32,
                                     num_message_passing_steps=2,
                                     split_first_layer=split)
      p = m.init(jax.random.key(0), *args)
      cost = jax.jit(m.apply).lower(p, *args).compile().cost_analysis()
      cost = cost[0] if isinstance(cost, list) else cost
      measured[split] = cost["flops"]
    saved = (models.processor_flops(300, 3000, 32, 2, 2, False) -
             models.processor_flops(300, 3000, 32, 2, 2, True))
    self.assertGreater(saved, 0)
    np.testing.assert_allclose(measured[False] - measured[True], saved,
                               rtol=0.02)

  @parameterized.parameters(True, False)
  def test_permutation_equivariant(self, split):
    nf, pt, ef, s, r = _inputs(1)
    model = _tiny(split)
    params = model.init(jax.random.key(2), nf, pt, ef, s, r)
    perm = np.random.default_rng(3).permutation(N)
    inverse = np.argsort(perm)
    out = model.apply(params, nf, pt, ef, s, r)
    out_perm = model.apply(params, nf[perm], pt[perm], ef,
                           jnp.asarray(inverse)[s], jnp.asarray(inverse)[r])
    np.testing.assert_allclose(out_perm, out[perm], atol=1e-5)

  def test_padding_edges_change_nothing(self):
    nf, pt, ef, s, r = _inputs(4)
    model = _tiny()
    params = model.init(jax.random.key(0), nf, pt, ef, s, r)
    pad = 50
    out = model.apply(params, nf, pt, ef, s, r)
    out_padded = model.apply(
        params, nf, pt, jnp.concatenate([ef, jnp.ones((pad, 3))]),
        jnp.concatenate([s, jnp.full(pad, N, jnp.int32)]),
        jnp.concatenate([r, jnp.full(pad, N, jnp.int32)]))
    np.testing.assert_allclose(out_padded, out, atol=1e-6)


class SmoothCutoffTest(absltest.TestCase):
  """Messages that vanish at R make the model continuous in the positions."""

  def _receiver_output(self, model, params, distance):
    # Two nodes; node 1 sends to node 0 at ``distance`` (units of R), and
    # each has its self-edge. Edges longer than R are not in the graph.
    nf, pt, _, _, _ = _inputs(5, n=2, e=1)
    s = [0, 1] + ([1] if distance < 1 else [])
    ef = [[0, 0, 0], [0, 0, 0]] + ([[distance, 0, distance]]
                                   if distance < 1 else [])
    return model.apply(params, nf, pt, jnp.asarray(ef, jnp.float32),
                       jnp.asarray(s, jnp.int32),
                       jnp.asarray([0, 1, 0][:len(s)], jnp.int32))[0]

  def test_weight_by_hand(self):
    d = jnp.array([0.0, 0.4, 0.5, 0.75, 1.0, 1.3])
    np.testing.assert_allclose(models.cutoff_weight(d, 0.5),
                               [1, 1, 1, 0.5, 0, 0], atol=1e-6)
    slope = jax.vmap(jax.grad(lambda x: models.cutoff_weight(x, 0.5)))(d)
    np.testing.assert_allclose(slope[np.array([0, 2, 4, 5])], 0, atol=1e-6)
    np.testing.assert_allclose(slope[3], -np.pi, rtol=1e-5)

  def test_an_edge_enters_at_zero_weight(self):
    args = _inputs(6, n=2, e=3)
    jumps = {}
    for taper in (0.0, 0.5):
      model = models.EncodeProcessDecode(
          latent_size=16, num_message_passing_steps=2, smooth_cutoff=taper)
      params = model.init(jax.random.key(0), *args)
      inside = self._receiver_output(model, params, 1 - 1e-4)
      outside = self._receiver_output(model, params, 1 + 1e-4)
      jumps[taper] = float(jnp.max(jnp.abs(inside - outside)))
    # Without the taper the edge's message appears at full size.
    self.assertGreater(jumps[0.0], 1e-2)
    self.assertLess(jumps[0.5], 1e-5)

  def test_inner_edges_are_untouched(self):
    # Every edge shorter than (1 - taper) R: equal to the hard cutoff.
    nf, pt, ef, s, r = _inputs(7)
    ef = ef.at[:, 2].set(jnp.abs(ef[:, 2]) % 0.5)
    hard, smooth = (models.EncodeProcessDecode(
        latent_size=16, num_message_passing_steps=2, smooth_cutoff=t)
                    for t in (0.0, 0.5))
    params = hard.init(jax.random.key(0), nf, pt, ef, s, r)
    np.testing.assert_allclose(smooth.apply(params, nf, pt, ef, s, r),
                               hard.apply(params, nf, pt, ef, s, r),
                               atol=1e-6)

  def test_bad_taper(self):
    model = models.EncodeProcessDecode(latent_size=8, smooth_cutoff=1.5)
    with self.assertRaisesRegex(ValueError, "smooth_cutoff = 1.5; allowed"):
      model.init(jax.random.key(0), *_inputs(n=4, e=4))


class VelocityGateTest(absltest.TestCase):
  """The gate's logit as the model's last output, and what it does to a
  step: next velocity g (v + a)."""

  def setUp(self):
    super().setUp()
    self.stats = features.Stats(jnp.array([0.1, -0.2]), jnp.array([2.0, 4.0]),
                                jnp.array([0.01, -0.02]),
                                jnp.array([0.5, 0.25]))
    rng = np.random.default_rng(1)
    self.positions = jnp.asarray(rng.normal(size=(6, 10, 2)), jnp.float32)
    self.acc = jnp.asarray(rng.normal(size=(10, 2)), jnp.float32)

  def _next(self, logit):
    out = jnp.concatenate([self.acc, jnp.full((10, 1), logit)], -1)
    acc = features.gate_acceleration(self.positions, out, self.stats)
    return features.integrate(self.positions, acc, self.stats)

  def test_a_closed_gate_stops_the_sand_exactly(self):
    np.testing.assert_allclose(self._next(-40.0), self.positions[-1],
                               atol=1e-6)

  def test_an_open_gate_is_the_plain_step(self):
    np.testing.assert_allclose(
        self._next(40.0), features.integrate(self.positions, self.acc,
                                             self.stats), atol=1e-5)

  def test_half_open_halves_the_velocity(self):
    plain = features.integrate(self.positions, self.acc, self.stats)
    last = self.positions[-1]
    np.testing.assert_allclose(self._next(0.0) - last, (plain - last) / 2,
                               atol=1e-5)

  def test_the_gate_starts_the_same_for_every_node(self):
    model = models.EncodeProcessDecode(
        latent_size=16, num_message_passing_steps=2, type_embedding_size=4,
        velocity_gate=True)
    args = _inputs(3)
    out = model.apply(model.init(jax.random.key(0), *args), *args)
    self.assertEqual(out.shape, (N, 3))
    np.testing.assert_allclose(out[:, 2], models.GATE_LOGIT_INIT, rtol=1e-6)
    # The acceleration head is the ungated model's, parameter for
    # parameter.
    plain = models.EncodeProcessDecode(
        latent_size=16, num_message_passing_steps=2, type_embedding_size=4)
    params = model.init(jax.random.key(0), *args)
    del params["params"]["velocity_gate"]
    np.testing.assert_allclose(plain.apply(params, *args), out[:, :2],
                               atol=1e-6)


def _linear_sdf() -> geometry.SDFGrid:
  """A linear SDF on a 0.5 m grid (bilinear interpolation is exact):
  phi = 0.6 x - 0.8 y + 0.3, outward normal (0.6, -0.8)."""
  x, y = np.meshgrid(np.arange(9) * 0.5, np.arange(5) * 0.5, indexing="ij")
  values = np.stack([0.6 * x - 0.8 * y + 0.3, np.full_like(x, 0.6),
                     np.full_like(x, -0.8)], -1)
  return geometry.SDFGrid(jnp.asarray(values, jnp.float32), 0.5)


class FeaturesTest(absltest.TestCase):

  def setUp(self):
    super().setUp()
    self.stats = features.Stats(jnp.array([0.1, -0.2]), jnp.array([2.0, 4.0]),
                                jnp.array([0.0, -1.0]), jnp.array([0.5, 0.25]))

  def test_node_features_by_hand(self):
    # Three particles, 3 frames: velocities (1, 0), (2, 1); (0, 0), (0, 0);
    # (0, 0), (0, 0).
    positions = jnp.array([[[0.5, 0.5], [0.2, 0.9], [1.0, 1.0]],
                           [[1.5, 0.5], [0.2, 0.9], [1.0, 1.0]],
                           [[3.5, 1.5], [0.2, 0.9], [1.0, 1.0]]])
    solids = _linear_sdf()
    got = np.asarray(features.node_features(positions, self.stats, solids,
                                            solid_range=0.5))
    self.assertEqual(got.shape, (3, features.num_node_features(3)))
    v0 = [(1 - 0.1) / 2, (0 + 0.2) / 4, (2 - 0.1) / 2, (1 + 0.2) / 4]
    v1 = [(0 - 0.1) / 2, (0 + 0.2) / 4] * 2
    # phi / R clipped to [-1, 1], then the normal times clip(1 - phi / R):
    # (3.5, 1.5): phi = 1.2, far (2.4 R): clipped to 1, no normal.
    # (0.2, 0.9): phi = -0.3 (inside, -0.6 R): weight 1.6 -> 1.
    # (1.0, 1.0): phi = 0.1 (0.2 R): weight 0.8.
    s0 = [1.0, 0.0, 0.0]
    s1 = [-0.6, 0.6, -0.8]
    s2 = [0.2, 0.8 * 0.6, 0.8 * -0.8]
    np.testing.assert_allclose(got, [v0 + s0, v1 + s1, v1 + s2], atol=1e-6)

  def test_predict_sees_the_solids_over_the_models_solid_range(self):
    # The particle at (2.0, 1.0) has phi = 0.7: beyond R = 0.5 (no
    # normal), within S = 1.0 (weight 0.3).
    solids = _linear_sdf()
    positions = jnp.array([[[2.0, 1.0], [0.2, 0.9]]] * 3)
    g = simulator.Graph(positions, jnp.zeros(2, jnp.int32),
                        jnp.ones(2, bool), jnp.array([0, 1]),
                        jnp.array([1, 0]), solids)
    ctx = simulator.Context(self.stats)
    seen = lambda s: features.node_features(positions, self.stats, solids, s)
    np.testing.assert_allclose(seen(1.0)[0, -3:], [0.7, 0.18, -0.24],
                               atol=1e-6)
    np.testing.assert_allclose(seen(0.5)[0, -3:], [1.0, 0.0, 0.0], atol=1e-6)
    edge_f = features.edge_features(positions[-1], g.senders, g.receivers,
                                    0.5)
    kwargs = dict(latent_size=8, num_message_passing_steps=1,
                  type_embedding_size=2)
    params = models.init_params(models.EncodeProcessDecode(**kwargs),
                                jax.random.key(0), seen(0.5).shape[-1])
    for solid_range, expected_range in ((None, 0.5), (1.0, 1.0)):
      model = models.EncodeProcessDecode(solid_range=solid_range, **kwargs)
      want = model.apply(params, seen(expected_range), g.particle_type,
                         edge_f, g.senders, g.receivers)
      np.testing.assert_allclose(
          simulator.predict(model, params, g, ctx, radius=0.5), want,
          atol=1e-6)
    far = models.EncodeProcessDecode(solid_range=1.0, **kwargs)
    near = models.EncodeProcessDecode(**kwargs)
    self.assertGreater(
        np.abs(simulator.predict(far, params, g, ctx, 0.5)
               - simulator.predict(near, params, g, ctx, 0.5)).max(), 1e-4)

  def test_edge_features_by_hand(self):
    position = jnp.array([[0.0, 0.0], [0.3, 0.4]])
    got = features.edge_features(position, jnp.array([1, 0]),
                                 jnp.array([0, 0]), radius=0.5)
    np.testing.assert_allclose(got, [[0.6, 0.8, 1.0], [0.0, 0.0, 0.0]],
                               atol=1e-6)

  def test_fold_noise_by_hand(self):
    # Stds grow to sqrt(std^2 + 3^2); means stay.
    folded = features.fold_noise(self.stats, 3.0)
    np.testing.assert_allclose(folded.vel_std, [np.sqrt(13.0), 5.0],
                               rtol=1e-6)
    np.testing.assert_allclose(folded.acc_std, [np.sqrt(9.25),
                                                np.sqrt(9.0625)], rtol=1e-6)
    np.testing.assert_array_equal(folded.vel_mean, self.stats.vel_mean)
    np.testing.assert_array_equal(folded.acc_mean, self.stats.acc_mean)
    unchanged = features.fold_noise(self.stats, 0.0)
    for a, b in zip(unchanged, self.stats):
      np.testing.assert_allclose(a, b, rtol=1e-7)
    # Works on host statistics too (``Problem.stats`` are numpy).
    host = features.Stats(*(np.asarray(a) for a in self.stats))
    np.testing.assert_allclose(features.fold_noise(host, 3.0).vel_std,
                               folded.vel_std, rtol=1e-6)

  def test_integrate_inverts_target_acceleration(self):
    rng = np.random.default_rng(0)
    positions = jnp.asarray(rng.normal(size=(6, 10, 2)), jnp.float32)
    target = jnp.asarray(rng.normal(size=(10, 2)), jnp.float32)
    acc = features.target_acceleration(positions, target, self.stats)
    np.testing.assert_allclose(features.integrate(positions, acc, self.stats),
                               target, atol=1e-5)


class NoiseTest(absltest.TestCase):

  def test_random_walk_statistics(self):
    std = 3e-4
    n = noise.random_walk(jax.random.key(0), (7, 20000, 2), std)
    n = np.asarray(n)
    np.testing.assert_array_equal(n[0], 0.0)
    v = np.diff(n, axis=0)                       # velocity noise, [6, N, 2]
    # The walk's last velocity has std `std`; step k has std*sqrt(k/6).
    for k in range(6):
      np.testing.assert_allclose(v[k].std(), std * np.sqrt((k + 1) / 6),
                                 rtol=0.03)
    increments = np.diff(v, axis=0, prepend=0)
    corr = np.corrcoef(increments[1].ravel(), increments[2].ravel())[0, 1]
    self.assertLess(abs(corr), 0.03)
    self.assertLess(abs(v.mean()), 3 * std / np.sqrt(v.size))

  def test_adjusted_target_keeps_the_true_velocity(self):
    rng = np.random.default_rng(1)
    window = jnp.asarray(rng.normal(size=(7, 5, 2)), jnp.float32)
    n = noise.random_walk(jax.random.key(1), (6, 5, 2), 1e-2)
    noisy_last = window[5] + n[-1]
    target = simulator.shift_target(window[6], n[-1], jnp.ones(5, bool))
    np.testing.assert_allclose(target - noisy_last, window[6] - window[5],
                               atol=1e-6)


if __name__ == "__main__":
  absltest.main()
