"""Losses: adversarial (``gan``)."""

from mesh2tex.losses.gan import GanLoss, GanLossConfig

__all__ = ["GanLoss", "GanLossConfig"]
