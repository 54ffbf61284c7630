"""`mesh2tex train noc --shapes DIR --out RUN [--config YAML] [--iters N] [--batch B] [--samples N] [--resume]`.

Trains the NOC U-Net (RGB + mask in, normalised object coordinates out) on rendered views of
prepared shapes; see :mod:`train.view_nets` for the data and the loop.
"""

from train.view_nets import add_view_arguments, run_view_training


def add_arguments(parser) -> None:
    add_view_arguments(parser, "noc")


def run(args) -> int:
    return run_view_training(args, "noc")
