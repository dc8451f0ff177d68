"""A tiny dataset that generates in seconds (tests and smoke runs)."""

from experiments.configs import paper


def get_config():
  config = paper.get_config()
  config.dataset.num_train = 3
  config.dataset.num_test = 7             # one of each test group
  config.dataset.num_frames = 20
  config.dataset.spacing = 0.01
  config.dataset.connectivity_radius = 0.03
  config.workers = 1
  return config
