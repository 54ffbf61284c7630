"""The small correct inputs of the library's shape-check tests and the check every case runs."""

from __future__ import annotations

import re
from types import SimpleNamespace

import pytest
import torch

from mesh2tex.geometry import prepared, primitives
from mesh2tex.losses import ot_style, style
from mesh2tex.losses.gan import GanLoss, GanLossConfig
from mesh2tex.nn.pose import PoseBins
from mesh2tex.transfer import optimise, pose
from mesh2tex.transfer.config import TransferConfig
from mesh2tex.transfer.photo import FramedView, Photo

R = 64  # the side of the small photos and views: three style scales need 16 px at the coarsest


def stand_in_layers(images, depth=None):
    """A stand-in for the VGG19 features: the image itself and its 2x2 average, as the style losses read them."""
    return [images, torch.nn.functional.avg_pool2d(images, 2)][: 2 if depth is None else depth]


def correct_inputs() -> SimpleNamespace:
    """Small correct inputs that the cases below break one argument at a time."""
    g = torch.Generator().manual_seed(0)
    images, masks = torch.rand(2, 3, 32, 32, generator=g), torch.zeros(2, 1, 32, 32)
    masks[..., 4:28, 4:28] = 1
    photo_mask = torch.zeros(1, 1, R, R)
    photo_mask[..., 8:56, 12:52] = 1
    photo = Photo(image=torch.rand(1, 3, R, R, generator=g) * 2 - 1, mask=photo_mask)
    view = FramedView(
        mvp=torch.eye(4)[None],
        render_size=R,
        box=(0, 0, R),
        noc=torch.rand(R, R, 3, generator=g),
        mask=photo_mask.clone(),
        azimuth=0.0,
        elevation=20.0,
        distance=2.0,
        fov=40.0,
    )
    cfg = TransferConfig(resolution=R)
    vertices, quads = primitives.cube_sphere(2)
    gan = GanLoss(GanLossConfig(), None, None)
    gan.set_colour_target(images * 2 - 1, masks)
    return SimpleNamespace(
        images=images,
        masks=masks,
        photo=photo,
        view=view,
        cfg=cfg,
        noc=torch.rand(R, R, 3, generator=g),
        vertices=vertices,
        quads=quads,
        triangles=prepared.quads_to_triangles(quads),
        gan=gan,
        loss=optimise.PhotoLoss(photo, view, torch.rand(R, R, 3, generator=g), stand_in_layers, cfg, "cpu"),
        exemplar=ot_style.ExemplarFeatures.compute(stand_in_layers, images[:1] * 2 - 1, 1),
        sets=[torch.rand(20, 3, generator=g), torch.rand(10, 3, generator=g)],
        beliefs=pose.PoseBeliefs(PoseBins(), torch.full((12,), 1 / 12), torch.full((5,), 0.2)),
    )


def pair_sets():
    return style.PatchPairs(torch.tensor([[30, 30]]), torch.tensor([[30, 30]]))


ANY = r"must have shape"
# name: (a correct call, the same call with one argument wrong, the error, a regex its message must match)


def check_case(cases: dict, case: str, w: SimpleNamespace) -> None:
    """The correct call (when the table gives one) runs through; the wrong one raises the case's error whose
    message starts with the function's name (the case's first word) and matches the case's regex."""
    function, _, argument = case.partition(" ")
    good, bad, error, message = cases[case]
    if good is not None:
        good(w)
    with pytest.raises(error, match=f"^{re.escape(function)}: ") as caught:
        bad(w)
    assert re.search(message, str(caught.value)), f"{argument}: {caught.value}"
