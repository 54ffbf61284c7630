"""Learning-rate schedules shared by the optimisations that settle at the end of a fixed budget."""

import math


def cosine_rate(lr: float, lr_end: float, iteration: int, iters: int) -> float:
    """The rate at step ``iteration`` of ``iters``: a half cosine from ``lr`` down to ``lr * lr_end`` at the
    last step (``lr_end`` 1 keeps it constant). Steps past the last keep the last rate."""
    progress = min(iteration / max(iters - 1, 1), 1.0)
    return lr * (lr_end + (1 - lr_end) * 0.5 * (1 + math.cos(math.pi * progress)))
