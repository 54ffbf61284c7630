"""`mesh2tex train mask --shapes DIR --out RUN [--config YAML] [--iters N] [--batch B] [--samples N] [--resume
[CHECKPOINT]]`.

Trains the mask U-Net (RGB in, the object's mask out) on rendered views of prepared shapes placed
over busy backdrops; ``infer transfer`` uses it for photos without a mask. See :mod:`train.view_nets`
for the data and the loop.
"""

from mesh2tex.train.view_nets import build_view_config, run_view_training


def build_config(args):
    """The resolved training config (what --print-config prints)."""
    return build_view_config(args)


def run(args) -> int:
    return run_view_training(args, "mask")
