"""The paper's settings: dataset (Table 1) and the GNS of section II.A."""

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
  # "mu_i" makes a dataset of the mu(I) rheology (docs/physics.md).
  config.dataset.rheology = "drucker_prager"
  config.workers = 2                      # dataset generation processes

  # Model: encoder, M message-passing steps, decoder.
  config.model = ml_collections.ConfigDict()
  config.model.latent_size = 128
  config.model.hidden_layers = 2
  config.model.num_message_passing_steps = 10
  config.model.type_embedding_size = 16
  config.model.split_first_layer = True
  # Messages taper to zero over this fraction of R before the cutoff, so the
  # model is a continuous function of the positions (gnsjax.models); 0: off.
  config.model.smooth_cutoff = 0.0
  # The model also scales each step's velocity by a learned factor in
  # (0, 1), so resting sand can stop exactly (gnsjax.models).
  config.model.velocity_gate = False
  # Distance (m) over which the node features see the solids (the signed
  # distance, clipped, and the normal fading to zero there); None: the
  # connectivity radius. It costs nothing: the SDF covers the whole domain.
  config.model.solid_range = ml_collections.FieldReference(
      None, field_type=float)
  # None: the dataset's connectivity radius.
  config.model.connectivity_radius = ml_collections.FieldReference(
      None, field_type=float)
  # Static boundary particles (ramp and obstacle outlines) as graph nodes.
  # The solids are always seen through the scene's signed distance field
  # (node features); boundary particles add a second, costlier view.
  config.model.boundary_particles = True
  # Node spacing of the SDF grid (m); None: R / 6.
  config.model.sdf_spacing = ml_collections.FieldReference(
      None, field_type=float)

  # Training.
  config.train = ml_collections.ConfigDict()
  config.train.seed = 0
  config.train.batch_size = 2
  config.train.num_steps = 2_000_000
  config.train.input_frames = 6
  config.train.frame_stride = 1           # stored frames per learned step
  config.train.noise_std = 3e-4           # m/step, velocity random walk
  # If > 0: noise = this fraction of the data's velocity std at the stride
  # (replaces noise_std).
  config.train.noise_velocity_fraction = 0.0
  # Divide by sqrt(std^2 + noise^2) (DeepMind's, geoelements', LagrangeBench).
  config.train.fold_noise = False
  # 0: windows uniformly; p > 0: weight (1 - p) + p * speed / mean speed.
  config.train.motion_weighting = 0.0
  # Pushforward: with this probability per batch, the model first rolls its
  # inputs this many steps on (no gradient) and learns from its own output.
  config.train.pushforward_steps = 0
  config.train.pushforward_probability = 0.0
  # The pushforward steps use the solid constraint, as a rollout does; off,
  # the model sees (and learns to leave) its own steps into a solid.
  config.train.pushforward_constrained = True
  # Rest pushforward: with this probability per batch that does not push
  # forward, the windows whose sand is still (noise.STILL_SPEED) are rolled
  # this many steps on by the model and keep their one-step target, so the
  # model learns to stop its own deposit's slow drift (docs/gns.md).
  config.train.rest_pushforward_steps = 0
  config.train.rest_pushforward_probability = 0.0
  # Still: mean speed below this over the whole window (m per stored frame;
  # noise.STILL_SPEED, 0.8 mm/s).
  config.train.rest_pushforward_speed = 2e-6
  # The still windows' target moves with the model's drift, as with noise:
  # the model learns to stop where its own steps took the sand, not to
  # return to the truth.
  config.train.rest_pushforward_stay = False
  # Unrolled training: with this probability per batch (drawn before
  # pushforward, which it replaces on that batch), the loss is taken through
  # this many learned steps of the model's own rollout, with the gradient
  # through all of them (gnsjax.unrolled); 0 or 1 step is one-step training.
  config.train.unroll_steps = 0
  config.train.unroll_probability = 0.0
  # ... only on batches with no still window: those keep the rest
  # pushforward, which an unrolled batch would take from them.
  config.train.unroll_moving_only = False
  # Noisy targets pushed out of the solids (simulator.add_noise): the model
  # learns to step out of a solid instead of staying inside.
  config.train.target_outside_solids = False
  # This fraction of the training windows gets no noise (drawn per window):
  # the model also sees sand exactly at rest, whose target is exactly zero.
  config.train.clean_fraction = 0.0
  # ... only among windows whose sand rests (noise.resting: mean speed below
  # 0.1 mm per stored frame); the moving ones all keep their noise.
  config.train.clean_resting_only = False
  # The clean windows' loss counts this many times: their targets (exact
  # rest) are small beside the moving windows'. 10 did not lower the rest
  # floor, and from scratch it raised it (docs/gns_log.md).
  config.train.clean_weight = 1.0
  # 0: those windows get no noise; m > 0: their noise std is scaled by a
  # factor drawn log-uniformly in [m, 1] per window (noise.quiet_scale),
  # down to the small jitter of a resting rollout.
  config.train.clean_scale_min = 0.0
  # Gather training windows on the device from the whole split stored there
  # (batching.DeviceWindows) instead of reading them on the host; needs
  # model.boundary_particles = False.
  config.train.device_windows = False
  # Fine-tuning: a run directory whose latest checkpoint's parameters (and
  # statistics) a new run starts from, at step 0; '': random initialisation.
  config.train.init_from = ""
  # Only these top-level modules learn (comma-separated, e.g.
  # 'velocity_gate'); the others keep their values. '': all of them.
  config.train.trainable = ""
  # Stop (with a checkpoint) after this much training time (s); 0: never.
  config.train.max_wall_time_s = 0.0
  config.train.lr_init = 1e-4
  config.train.lr_min = 1e-6
  config.train.lr_decay_steps = 5_000_000
  config.train.clip_norm = 1.0
  config.train.node_bucket = 128
  config.train.capacity_multiplier = 1.25

  # Checkpoints: every_steps, and the paper's V1-V4.
  config.checkpoint = ml_collections.ConfigDict()
  config.checkpoint.every_steps = 10_000
  config.checkpoint.named_steps = (500_000, 1_000_000, 1_500_000, 2_000_000)
  config.checkpoint.keep = 3

  # Validation during training.
  config.eval = ml_collections.ConfigDict()
  config.eval.every_steps = 50_000
  config.eval.num_windows = 64
  config.eval.rollout_steps = 50
  config.eval.num_rollouts = 4

  config.log_every = 100
  return config
