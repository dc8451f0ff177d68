"""A small problem trainable on one CPU core in about four hours: coarser
particles (spacing 0.01 m, 175-250 per scene), the paper's 1000 training
and 100 test trajectories, a smaller model (latent 64, 5 message-passing
steps), and the recipe that learns rest (docs/gns.md)."""

from experiments.configs import paper


def get_config():
  config = paper.get_config()
  config.dataset.num_train = 1000
  config.dataset.num_test = 100           # 14-15 of each of the 7 groups
  config.dataset.spacing = 0.01
  config.dataset.connectivity_radius = 0.03

  config.model.latent_size = 64
  config.model.num_message_passing_steps = 5

  # The long-horizon recipe (docs/gns.md, ablation): the solids seen
  # through the SDF only, a learned step of 3 stored frames (7.5 ms), noise
  # scaled to the data's velocity std and folded into the normalisation,
  # windows weighted toward moving sand. The noise at 0.25 of the velocity
  # std (the resting heap's error amplitude in a rollout) makes the deposit
  # come to rest; at 0.1 it never did (docs/gns.md, "Learning rest").
  config.model.boundary_particles = False
  config.train.frame_stride = 3
  config.train.noise_velocity_fraction = 0.25
  config.train.fold_noise = True
  config.train.motion_weighting = 0.5
  # Noisy targets pushed out of the solids: the resting heap stops leaning
  # on the solid constraint (docs/gns.md). The shipped model learned it in
  # a 12000-step fine-tuning at lr 2e-5 (provenance.json); from scratch
  # with it, the same 40000 steps did worse (docs/gns_log.md).
  config.train.target_outside_solids = True

  config.train.num_steps = 40000
  config.train.lr_init = 3e-4
  config.train.lr_decay_steps = 40000
  config.train.node_bucket = 64
  config.checkpoint.every_steps = 500
  # Kept for the shipped model, the mean of the last five (docs/gns_log.md):
  # one checkpoint is one draw from a wide spread.
  config.checkpoint.named_steps = (8000, 16000, 24000, 32000, 34000, 36000,
                                   38000, 40000)
  config.eval.every_steps = 4000
  config.eval.num_windows = 32
  config.eval.num_rollouts = 3
  config.log_every = 50
  return config
