"""The one conversion of colours to uint8 at the file boundary, the one compositing over a background,
and the one JSON cleaning: the conventions every writer relies on."""

from __future__ import annotations

import json
import math

import numpy as np
import torch

from mesh2tex.io.atomic import json_ready
from mesh2tex.io.images import colours_to_uint8, images_to_uint8
from mesh2tex.render import composite, composite_images


def test_colours_become_uint8_clamped_and_rounded_half_to_even():
    signed = torch.tensor([-2.0, -1.0, 0.0, 1.0, 3.0, 1 / 127.5 - 1])
    assert colours_to_uint8(signed).tolist() == [0, 0, 128, 255, 255, 1]  # 0 -> 127.5 -> 128 (half to even)
    unit = torch.tensor([-0.5, 0.0, 0.5, 1.0, 2.0, 2.5 / 255])
    assert colours_to_uint8(unit, signed=False).tolist() == [0, 0, 128, 255, 255, 2]  # 2.5 -> 2 (half to even)
    images = torch.rand(2, 3, 4, 5) * 2 - 1
    out = images_to_uint8(images)
    assert out.shape == (2, 4, 5, 3) and out.dtype == np.uint8
    assert np.array_equal(out[1, 2, 3], colours_to_uint8(images[1, :, 2, 3]))


def test_compositing_is_one_formula_in_both_layouts():
    images, masks = torch.rand(2, 3, 4, 4), (torch.rand(2, 1, 4, 4) > 0.5).float()
    colours = torch.rand(2, 3)
    out = composite_images(images, masks, colours)
    assert torch.equal(out, images * masks + colours[:, :, None, None] * (1 - masks))
    assert torch.equal(composite_images(images, masks, 1.0), images * masks + (1 - masks))
    channels_last = composite(images.permute(0, 2, 3, 1), masks.permute(0, 2, 3, 1), colours[0])
    assert torch.equal(
        channels_last.permute(0, 3, 1, 2), composite_images(images, masks, colours[0][None].expand(2, 3))
    )


def test_json_ready_writes_strict_json():
    value = {"a": (1, 2.5), "b": [float("nan"), float("inf"), -math.inf], "c": {"d": "x"}}
    ready = json_ready(value)
    assert ready == {"a": [1, 2.5], "b": [None, "inf", "-inf"], "c": {"d": "x"}}
    json.dumps(ready, allow_nan=False)
