"""The paper's settings: 1000 training and 100 test trajectories of 600 frames."""

import ml_collections


def get_config() -> ml_collections.ConfigDict:
  config = ml_collections.ConfigDict()

  # Dataset (Table 1 of the paper; see mpm.dataset.DatasetSpec).
  config.dataset = ml_collections.ConfigDict()
  config.dataset.num_train = 1000
  config.dataset.num_test = 100
  config.dataset.num_frames = 600
  config.dataset.seed = 0
  config.dataset.spacing = 0.005          # m; 700-1000 particles per scene
  config.dataset.connectivity_radius = 0.015

  # Generation.
  config.workers = 2                      # processes simulating in parallel
  return config
