"""The three image networks of texture transfer, the pose classifier, the NOC U-Net and the mask
U-Net: the config they are trained with (kept in their checkpoints) and their construction from it.

``mesh2tex train pose|noc|mask`` trains them (:mod:`train.view_nets`); :func:`mesh2tex.models.load_view_network`
reads them back.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch

from mesh2tex.config import MAX_CHANNELS, check_fields
from mesh2tex.nn.mask import MaskUNet
from mesh2tex.nn.noc import NocUNet
from mesh2tex.nn.pose import PoseBins, PoseNet
from mesh2tex.render import RenderSettings

VIEWS_NAME = "views.npz"  # where a 'train pose|noc|mask' run directory caches its rendered views


@dataclass
class ViewDataConfig:
    category: str = "chair"  # material library of the renders: 'chair' or 'car'
    # which world's materials: 'boxy' (the original procedural library) or 'real' (materials a photo would show)
    variety: str = "boxy"
    samples: int = 512  # rendered views in all (training plus held-out)
    views_per_material: int = 4  # views that share one random material and shape
    holdout: float = 0.1  # share of the views kept for validation
    resolution: int = 128  # side of the rendered views (and the network input)
    supersample: int = 1  # render at this multiple and average (anti-aliasing)
    elevation_min: float = 5.0  # degrees; match the photos you will query with
    elevation_max: float = 35.0  # degrees
    distance_min: float = 1.5  # camera distance range (shapes have bbox diagonal 1)
    distance_max: float = 1.9
    fov: float = 40.0  # vertical field of view, degrees
    # crop each view to the square around its object with this margin, as 'infer transfer' crops the photo (< 0:
    # keep the whole frame)
    frame_margin: float = 0.1
    frame_oversample: int = 2  # render framed views at this multiple of ``resolution`` before cropping
    # a 'train gan' checkpoint that textures a share of the groups; '' = procedural materials only
    gan_checkpoint: str = ""
    gan_share: float = 0.5  # share of the view groups textured by the GAN when gan_checkpoint is given

    def __post_init__(self):
        check_fields(
            self,
            at_least={"views_per_material": 1, "frame_oversample": 1},
            positive=("distance_min",),
            between={
                "holdout": (0.0, 0.9),
                "fov": (1.0, 179.0),
                "elevation_min": (-90.0, 90.0),
                "elevation_max": (-90.0, 90.0),
            },
        )
        _ = self.render_settings  # checks resolution and supersample
        if self.distance_min > self.distance_max or self.elevation_min > self.elevation_max:
            raise ValueError(
                f"distance {self.distance_min}..{self.distance_max}, elevation "
                f"{self.elevation_min}..{self.elevation_max}: a range's minimum is above its maximum"
            )

    @property
    def render_settings(self) -> RenderSettings:
        """How each view is rendered before framing: framed views (``frame_margin`` >= 0) at ``frame_oversample``
        times ``resolution``, then cropped around their object and resized to ``resolution``."""
        framed = self.frame_margin >= 0
        return RenderSettings(self.resolution * (self.frame_oversample if framed else 1), self.supersample)


@dataclass
class ViewTrainConfig:
    seed: int = 0  # seed of the renders, the initialisation and the mini-batches
    iters: int = 2000  # optimisation steps
    batch: int = 32  # views per step
    lr: float = 3e-4  # Adam learning rate (paper: 3e-4 for chairs)
    # the rate at the last step, as a fraction of lr: a cosine over --iters in between (1: constant)
    lr_end: float = 1.0
    width: int = 32  # channel width of the network's first level
    device: str = "auto"  # auto, cpu or cuda
    log_every: int = 25  # steps between metrics.jsonl records (with validation figures)
    checkpoint_every: int = 250  # steps between checkpoints (0: only at the end)
    # mask only: the share of training views placed standing on the floor of a drawn room instead of over a
    # backdrop (mesh2tex.synthetic.backdrops.room); 0 draws what the networks shipped before rooms learnt from
    room_share: float = 0.0
    # mask only: the share of scenes (rooms or backdrops) tinted to the object's mean colour
    # (mesh2tex.synthetic.backdrops.camouflage); 0 draws what the networks shipped before it learnt from
    camouflage_share: float = 0.0
    # mask only: the share of scenes with other rounded things drawn behind the object
    # (mesh2tex.synthetic.backdrops.add_distractors); 0 draws what the networks shipped before it learnt from
    distractor_share: float = 0.0
    data: ViewDataConfig = field(default_factory=ViewDataConfig)
    bins: PoseBins = field(default_factory=PoseBins)  # pose classes (used by 'pose' only)

    def __post_init__(self):
        check_fields(
            self,
            positive=("lr",),
            at_least={"log_every": 1, "checkpoint_every": 0},
            between={
                "width": (1, MAX_CHANNELS),
                "room_share": (0.0, 1.0),
                "camouflage_share": (0.0, 1.0),
                "distractor_share": (0.0, 1.0),
                "lr_end": (0.0, 1.0),
            },
        )


def build_network(kind: str, cfg: ViewTrainConfig) -> torch.nn.Module:
    """A fresh ``kind`` network ('pose', 'noc' or 'mask') of ``cfg``'s width (and, for 'pose', its bins)."""
    if kind == "pose":
        return PoseNet(bins=cfg.bins, width=cfg.width)
    if kind == "noc":
        return NocUNet(width=cfg.width)
    if kind == "mask":
        return MaskUNet(width=cfg.width)
    raise ValueError(f"unknown network kind {kind!r}")
