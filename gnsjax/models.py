"""The graph network simulator: encoder, M message-passing steps, decoder.

Flax linen, chosen over NNX because its parameters are plain pytrees that go
straight into ``jax.jit``, optax, orbax and ``jax.sharding`` (measured with
flax 0.12.8 on the development CPU: NNX's per-step ``nnx.jit`` ran ~7x
slower, and matching linen needs an ``nnx.split``/``merge`` per step). Each
message-passing step is a ``jraph.GraphNetwork`` with unshared weights,
residual connections and a LayerNorm after every MLP except the decoder's.

The first layer of an edge MLP acts on [h_ij, h_i, h_j]. Written as
W_e h_ij + (W_s h)[senders] + (W_r h)[receivers], the node terms cost one
matmul per node instead of one per edge (``split_first_layer``). The node
projections travel to the edge function as node attributes; jraph gathers
every node attribute at both ends, and XLA removes the gathers that are not
used.

A smooth cutoff (``smooth_cutoff`` = w > 0, a trainable option) weights
each edge's message by a factor that is 1 up to (1 - w) R and falls as a
half cosine to 0 at R (``cutoff_weight``). An edge then enters the node
updates at zero weight when two nodes come within R, so the model's output
is a continuous (C^1) function of the positions: without it an edge's
message is of full size the moment it appears, and a rollout jumps. Only
the aggregation is weighted; edge states still carry their full message to
the next step's edge update, where it is weighted again before any node
sees it.

A velocity gate (``velocity_gate``, an option) adds a third output, the
logit z of a factor g = sigmoid(z) in (0, 1) by which the step's velocity is
scaled: v_{t+1} = g (v_t + a) (``features.gate_acceleration``). Sand that
rests can then stop exactly, as a friction does, instead of through an
acceleration that cancels its velocity to within the model's error; g is
learned, no speed threshold decides it. The gate head is linear in the
processor's node latents, starts at g = sigmoid(GATE_LOGIT_INIT) for every
node and learns GATE_GAIN times faster than the other weights (Adam's steps
are of the same size in every parameter).

Shapes: N nodes, E edges, L latent size.

References:
  Sanchez-Gonzalez et al. (2020), "Learning to simulate complex physics with
  graph networks".
"""

from typing import Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp
import jraph

NUM_PARTICLE_TYPES = 9
# The gate's initial logit: g = 0.982, a velocity 1.8% short at the first
# fine-tuning step, which the acceleration head learns back within a few
# hundred steps; at sigmoid's tails the gradient would vanish.
GATE_LOGIT_INIT = 4.0
GATE_GAIN = 100.0


class MLP(nn.Module):
  """Dense layers with ReLU between them, optionally LayerNorm at the end."""
  features: Sequence[int]
  layer_norm: bool = True

  @nn.compact
  def __call__(self, x):
    for i, size in enumerate(self.features):
      x = nn.Dense(size, name=f"dense_{i}")(x)
      if i < len(self.features) - 1:
        x = nn.relu(x)
    if self.layer_norm:
      x = nn.LayerNorm(name="norm")(x)
    return x


def cutoff_weight(distance: jax.Array, taper: float) -> jax.Array:
  """Message weights of edges of length ``distance`` (units of R) [E].

  1 below 1 - taper, 0.5 (1 + cos(pi (distance - 1 + taper) / taper)) from
  there to 1, 0 beyond: continuous with its first derivative. taper in
  (0, 1].
  """
  s = jnp.clip((distance - (1.0 - taper)) / taper, 0.0, 1.0)
  return 0.5 * (1.0 + jnp.cos(jnp.pi * s))


class InteractionBlock(nn.Module):
  """One message-passing step: edge update, then node update (residual)."""
  latent_size: int
  hidden_layers: int
  split_first_layer: bool = True

  @nn.compact
  def __call__(self, graph: jraph.GraphsTuple,
               edge_weight: jax.Array | None = None) -> jraph.GraphsTuple:
    """The updated graph; ``edge_weight`` [E] (if given) scales each edge's
    message in the sum a node receives."""
    hidden = [self.latent_size] * self.hidden_layers
    h = graph.nodes
    if self.split_first_layer:
      # The first edge layer, split: node terms once per node.
      nodes = {
          "h": h,
          "s": nn.Dense(self.latent_size, use_bias=False,
                        name="edge_sender")(h),
          "r": nn.Dense(self.latent_size, use_bias=False,
                        name="edge_receiver")(h),
      }
      edge_first = nn.Dense(self.latent_size, name="edge_in")
      edge_rest = MLP(hidden[1:] + [self.latent_size], name="edge_mlp")

      def update_edge_fn(e, sent, received, globals_):
        del globals_
        x = nn.relu(edge_first(e) + sent["s"] + received["r"])
        return e + edge_rest(x)
    else:
      nodes = {"h": h}
      edge_mlp = MLP(hidden + [self.latent_size], name="edge_mlp")

      def update_edge_fn(e, sent, received, globals_):
        del globals_
        return e + edge_mlp(jnp.concatenate([e, sent["h"], received["h"]],
                                            -1))

    node_mlp = MLP(hidden + [self.latent_size], name="node_mlp")

    def update_node_fn(nodes, sent, received, globals_):
      del sent, globals_
      return nodes["h"] + node_mlp(jnp.concatenate([nodes["h"], received], -1))

    def aggregate(edges, receivers, num_nodes):
      if edge_weight is not None:
        edges = edges * edge_weight[:, None]
      return jraph.segment_sum(edges, receivers, num_nodes)

    network = jraph.GraphNetwork(update_edge_fn=update_edge_fn,
                                 update_node_fn=update_node_fn,
                                 aggregate_edges_for_nodes_fn=aggregate)
    return network(graph._replace(nodes=nodes))


class EncodeProcessDecode(nn.Module):
  """Node accelerations from node and edge features.

  Attributes:
    latent_size: L (128 in the paper).
    hidden_layers: hidden layers per MLP (2).
    num_message_passing_steps: M (10).
    type_embedding_size: size of the learned particle-type embedding.
    output_size: 2 (normalised acceleration).
    split_first_layer: see the module docstring.
    smooth_cutoff: taper width w of the messages, a fraction of R in [0,
      1]; 0 (default): a hard cutoff, every edge at full weight.
    velocity_gate: add the gate's logit as a last output (see above).
    solid_range: distance (m) over which the node features see the solids
      (``gnsjax.features.solid_features``); None: the connectivity radius.
      Read through ``seen_solid_range`` by whoever builds the node
      features (``gnsjax.simulator.predict``), not by the network.
  """
  latent_size: int = 128
  hidden_layers: int = 2
  num_message_passing_steps: int = 10
  type_embedding_size: int = 16
  output_size: int = 2
  split_first_layer: bool = True
  smooth_cutoff: float = 0.0
  velocity_gate: bool = False
  solid_range: float | None = None

  def seen_solid_range(self, radius: float) -> float:
    """S (m), the distance over which the node features see the solids:
    ``solid_range``, or the connectivity radius ``radius`` (m)."""
    return self.solid_range or radius

  @nn.compact
  def __call__(self, node_features: jax.Array, particle_type: jax.Array,
               edge_features: jax.Array, senders: jax.Array,
               receivers: jax.Array) -> jax.Array:
    """Normalised accelerations [N, output_size], then with
    ``velocity_gate`` the gate's logit z [N, 1].

    Args:
      node_features: [N, F] (``features.node_features``).
      particle_type: int32 [N] in [0, NUM_PARTICLE_TYPES).
      edge_features: [E, 3] (``features.edge_features``: d / R, |d| / R).
      senders, receivers: int32 [E]; padding edges point at N (dropped).
    """
    if not 0.0 <= self.smooth_cutoff <= 1.0:
      raise ValueError(f"smooth_cutoff = {self.smooth_cutoff}; allowed: 0 "
                       "(off) to 1 (a fraction of the radius)")
    hidden = [self.latent_size] * self.hidden_layers
    embedding = nn.Embed(NUM_PARTICLE_TYPES, self.type_embedding_size,
                         name="type_embedding")(particle_type)
    nodes = MLP(hidden + [self.latent_size], name="node_encoder")(
        jnp.concatenate([node_features, embedding], -1))
    edges = MLP(hidden + [self.latent_size], name="edge_encoder")(
        edge_features)
    n = node_features.shape[0]
    graph = jraph.GraphsTuple(
        nodes=nodes, edges=edges, senders=senders, receivers=receivers,
        globals=None, n_node=jnp.array([n]),
        n_edge=jnp.array([senders.shape[0]]))
    weight = (cutoff_weight(edge_features[:, 2], self.smooth_cutoff)
              if self.smooth_cutoff > 0 else None)
    for m in range(self.num_message_passing_steps):
      graph = InteractionBlock(self.latent_size, self.hidden_layers,
                               self.split_first_layer, name=f"step_{m}")(
                                   graph, weight)
    acc = MLP(hidden + [self.output_size], layer_norm=False,
              name="decoder")(graph.nodes)
    if not self.velocity_gate:
      return acc
    logit = GATE_GAIN * nn.Dense(
        1, kernel_init=nn.initializers.zeros,
        bias_init=nn.initializers.constant(GATE_LOGIT_INIT / GATE_GAIN),
        name="velocity_gate")(graph.nodes)
    return jnp.concatenate([acc, logit], -1)


def processor_flops(n_nodes: int, n_edges: int, latent_size: int = 128,
                    hidden_layers: int = 2, steps: int = 10,
                    split_first_layer: bool = True) -> int:
  """Multiply-add FLOPs (2 per MAC) of the processor's dense layers."""
  l = latent_size
  rest = 2 * hidden_layers * l * l            # layers after the first
  if split_first_layer:
    edge = n_edges * 2 * (l * l + rest // 2) + n_nodes * 2 * (2 * l * l)
  else:
    edge = n_edges * 2 * (3 * l * l + rest // 2)
  node = n_nodes * 2 * (2 * l * l + rest // 2)
  return steps * (edge + node)


def split_to_concat_params(block_params: dict) -> dict:
  """Parameters of a concatenated-form block equal to a split-form block.

  The concatenated first edge layer's kernel is [W_e; W_s; W_r] stacked along
  the input axis (edge, sender, receiver, as concatenated in the edge
  function), with W_e's bias.
  """
  kernel = jnp.concatenate([block_params["edge_in"]["kernel"],
                            block_params["edge_sender"]["kernel"],
                            block_params["edge_receiver"]["kernel"]], 0)
  edge_mlp = {"dense_0": {"kernel": kernel,
                          "bias": block_params["edge_in"]["bias"]}}
  for name, value in block_params["edge_mlp"].items():
    if name.startswith("dense_"):
      edge_mlp[f"dense_{int(name.split('_')[1]) + 1}"] = value
    else:
      edge_mlp[name] = value
  return {"edge_mlp": edge_mlp, "node_mlp": block_params["node_mlp"]}


def init_params(model: EncodeProcessDecode, key: jax.Array,
                num_node_features: int):
  """Parameters of ``model`` for node features [N, num_node_features]
  (``features.num_node_features``); shapes do not depend on N or E."""
  n = e = 8
  return model.init(key, jnp.zeros((n, num_node_features)),
                    jnp.zeros((n,), jnp.int32), jnp.zeros((e, 3)),
                    jnp.zeros((e,), jnp.int32), jnp.zeros((e,), jnp.int32))
