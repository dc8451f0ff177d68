"""A tiny problem that runs in seconds (tests and smoke runs)."""

from experiments.configs import paper


def get_config():
  config = paper.get_config()
  config.dataset.num_train = 3
  config.dataset.num_test = 7             # one of each test group
  config.dataset.num_frames = 20
  config.dataset.spacing = 0.01
  config.dataset.connectivity_radius = 0.03
  config.workers = 1

  config.model.latent_size = 16
  config.model.hidden_layers = 1
  config.model.num_message_passing_steps = 2
  config.model.type_embedding_size = 4

  config.train.num_steps = 20
  config.train.lr_init = 1e-3
  config.train.lr_decay_steps = 1000
  config.train.node_bucket = 64
  config.checkpoint.every_steps = 5
  config.checkpoint.named_steps = (10,)
  config.eval.every_steps = 10
  config.eval.num_windows = 4
  config.eval.rollout_steps = 5
  config.eval.num_rollouts = 1
  config.log_every = 5
  return config
