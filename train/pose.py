"""`mesh2tex train pose --shapes DIR --out RUN [--config YAML] [--iters N] [--batch B] [--samples N] [--resume
[CHECKPOINT]]`.

Trains the pose classifier (azimuth in 12 bins, elevation in 5) on rendered views of
prepared shapes; see :mod:`train.view_nets` for the data and the loop.
"""

from mesh2tex.train.view_nets import build_view_config, run_view_training


def build_config(args):
    """The resolved training config (what --print-config prints)."""
    return build_view_config(args)


def run(args) -> int:
    return run_view_training(args, "pose")
