"""File boundary helpers: atomic writes, checkpoints, images, textured assets."""
