"""The tiny networks and runs that the robustness benchmarks train in seconds (``bad_inputs.py``, ``kill_runs.py``)."""

TINY_GENERATOR = {
    "z_dim": 16,
    "w_dim": 16,
    "mapping_layers": 2,
    "encoder_channels": [8, 8, 8],
    "synthesis_channels": [8, 8, 8],
    "field_hidden": 16,
    "aux_latent_dim": 8,
}
TINY_DISCRIMINATOR = {"channel_base": 64, "channel_max": 16}
# train gan: lazy terms every other iteration, a checkpoint every 2 (no samples)
TINY_GAN = {
    "sample_every": 0,
    "checkpoint_every": 2,
    "log_every": 1,
    "sample_shapes": 2,
    "generator": TINY_GENERATOR,
    "discriminator": TINY_DISCRIMINATOR,
    "loss": {"r1_interval": 2, "pl_interval": 2},
}
# train nca: a 6-channel automaton on a coarse sphere, a checkpoint every iteration (no samples)
TINY_NCA = {
    "batch": 1,
    "views": 1,
    "resolution": 32,
    "steps_min": 2,
    "steps_max": 3,
    "pool": 4,
    "seed_every": 2,
    "mesh": "sphere:3",
    "exemplar_size": 32,
    "vgg_depth": 1,
    "max_points": 64,
    "sample_every": 0,
    "checkpoint_every": 1,
    "log_every": 1,
    "nca": {"channels": 6, "hidden": 16},
}
