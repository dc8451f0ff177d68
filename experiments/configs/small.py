"""A small problem trainable on a 2-core CPU within an hour: coarser
particles (spacing 0.01 m, 175-250 per scene), 60 training scenes, a smaller
model (latent 64, 5 message-passing steps), 8000 steps."""

from experiments.configs import paper


def get_config():
  config = paper.get_config()
  config.dataset.num_train = 60
  config.dataset.num_test = 21            # 3 of each of the 7 test groups
  config.dataset.spacing = 0.01
  config.dataset.connectivity_radius = 0.03

  config.model.latent_size = 64
  config.model.num_message_passing_steps = 5

  config.train.num_steps = 8000          # ~30 min at ~4.5 steps/s here
  config.train.lr_init = 3e-4
  config.train.lr_decay_steps = 8000
  config.train.node_bucket = 64
  config.checkpoint.every_steps = 500
  config.checkpoint.named_steps = (2000, 4000, 6000, 8000)
  config.eval.every_steps = 2000
  config.eval.num_windows = 32
  config.eval.num_rollouts = 3
  config.log_every = 50
  return config
