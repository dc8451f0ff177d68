"""A small dataset trainable on a 2-core CPU: coarser particles, fewer scenes."""

from experiments.configs import paper


def get_config():
  config = paper.get_config()
  config.dataset.num_train = 60
  config.dataset.num_test = 21            # 3 of each of the 7 test groups
  config.dataset.spacing = 0.01           # 4x fewer particles (175-250)
  config.dataset.connectivity_radius = 0.03
  return config
