"""`mesh2tex train pose --shapes DIR --out RUN [--config YAML] [--iters N] [--batch B] [--samples N] [--resume]`.

Trains the pose classifier (azimuth in 12 bins, elevation in 5) on rendered views of
prepared shapes; see :mod:`train.view_nets` for the data and the loop.
"""

from train.view_nets import run_view_training
from train.view_nets import build_view_config as build_config  # noqa: F401  (--print-config)


def run(args) -> int:
    return run_view_training(args, "pose")
