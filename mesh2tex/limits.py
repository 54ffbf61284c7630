"""The largest sizes and the valid ranges every command accepts, checked before any allocation.

A size beyond these is a typo or a request no machine of ours can serve (a 100000-subdivision sphere
asks for 75 GiB): it is refused with one line naming the value and the maximum, before any array
is made. The maxima are far above anything a trained model or the docs use.

Config fields are checked by name wherever they appear (:func:`check_config_value`, called by
:func:`mesh2tex.config.config_from_dict` for every field a file or a flag sets), so that an
``elevation`` or a ``texture_size`` means the same range in every command; flags outside configs
call :func:`check_size` and :func:`check_range` themselves.
"""

from __future__ import annotations

import math

from mesh2tex.errors import InputError

MAX_RESOLUTION = 4096  # side of a render, a photo crop or an exemplar, pixels
MAX_TEXTURE_SIZE = 8192  # side of a baked UV texture, pixels
MAX_VIEWS = 10_000  # views, frames or samples of one command
MAX_FACES = 1_000_000  # quads of the finest level of a prepared shape
MAX_LEVELS = 10  # levels of a quad hierarchy (each a quarter of the one below; 4^9 from a million is 4 quads)
MAX_SPHERE_SUBDIVISIONS = 256  # sphere:N is a cube sphere of 6 N^2 quads (256: 393216)
MAX_IMAGE_PIXELS = 100_000_000  # pixels of one photo read (PIL's own bomb limit is half of twice this)
MAX_LATENTS = 10_000  # latents per shape of the generation protocol
MAX_BATCH = 4096  # shapes or views per training step
MAX_ITERS = 10_000_000  # optimisation steps of one command (training iterations, transfer stages)
MAX_NCA_STEPS = 100_000  # automaton steps of one rollout or growth
MIN_SET_PHOTO_SIDE = 8  # the smallest side of a photo of a training or evaluation set (prepare images' smallest --size)

ELEVATION = (-90.0, 90.0)  # degrees above the horizon
FOV = (1.0, 179.0)  # vertical field of view, degrees

# config field name -> (lowest, highest); a list field: each element
SIZE_FIELDS: dict[str, tuple[int, int]] = {
    "resolution": (0, MAX_RESOLUTION),
    "photo_resolution": (1, MAX_RESOLUTION),
    "exemplar_size": (1, MAX_RESOLUTION),
    "render_size": (1, MAX_RESOLUTION),
    "patch_size": (1, MAX_RESOLUTION),
    "texture_size": (1, MAX_TEXTURE_SIZE),
    "views": (1, MAX_VIEWS),
    "query_views": (1, MAX_VIEWS),
    "anchor_views": (0, MAX_VIEWS),
    "unseen_views": (0, MAX_VIEWS),
    "frames": (0, MAX_VIEWS),
    "turntable_frames": (0, MAX_VIEWS),
    "samples": (1, 100_000),
    "faces": (0, MAX_FACES),
    "latents": (1, MAX_LATENTS),
    "batch": (1, MAX_BATCH),
    "iters": (0, MAX_ITERS),
    "latent_iters": (0, MAX_ITERS),
    "refine_iters": (0, MAX_ITERS),
    "pose_iters": (0, MAX_ITERS),
    "noc_iters": (0, MAX_ITERS),
    "lr_decay_iters": (0, MAX_ITERS),
    "steps": (0, MAX_NCA_STEPS),
    "steps_min": (0, MAX_NCA_STEPS),
    "steps_max": (0, MAX_NCA_STEPS),
    "final_steps": (0, MAX_NCA_STEPS),
    "nca_steps": (0, MAX_NCA_STEPS),
}
ANGLE_FIELDS: dict[str, tuple[float, float]] = {
    "elevation": ELEVATION,
    "elevation_min": ELEVATION,
    "elevation_max": ELEVATION,
    "fov": FOV,
}
TRUNCATION = (-2.0, 2.0)  # truncation psi: 1 none, 0 the mean latent; beyond +-2 the latents leave anything trained
RANGE_FIELDS: dict[str, tuple[float, float]] = {"truncation": TRUNCATION}


def check_size(name: str, value, maximum: int, minimum: int = 1) -> int:
    """``value`` as an int in [minimum, maximum], else InputError naming ``name`` (a flag or field)."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{name}: expected a whole number, got {short(value)}")
    if value > maximum:
        raise InputError(f"{name} {value}: must be at most {maximum} (mesh2tex.limits)")
    if value < minimum:
        raise InputError(f"{name} {value}: must be at least {minimum}")
    return value


def check_range(name: str, value, low: float, high: float, unit: str = "") -> float:
    """``value`` as a finite float in [low, high] (an angle: ``unit`` "degrees"), else InputError naming ``name``."""
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{name}: expected a number, got {short(value)}") from None
    if not math.isfinite(number) or not low <= number <= high:
        raise InputError(f"{name} {short(value)}: must be in [{low:g}, {high:g}]{' ' + unit if unit else ''}")
    return number


def check_config_value(name: str, value, where: str) -> None:
    """The range of the config field ``name`` (:data:`SIZE_FIELDS`, :data:`ANGLE_FIELDS`), checked for
    ``value`` (each element of a list); ``where``: the file and dotted field, for the message."""
    values = value if isinstance(value, (list, tuple)) else [value]
    if name in SIZE_FIELDS:
        low, high = SIZE_FIELDS[name]
        for v in values:
            if isinstance(v, int) and not isinstance(v, bool):
                check_size(where, v, high, low)
    elif name in ANGLE_FIELDS or name in RANGE_FIELDS:
        for v in values:
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                check_range(
                    where,
                    v,
                    *ANGLE_FIELDS.get(name, RANGE_FIELDS.get(name)),
                    unit="degrees" if name in ANGLE_FIELDS else "",
                )


def short(value, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters: an error message quotes at most a line of a value."""
    import reprlib

    shortener = reprlib.Repr()
    shortener.maxstring = shortener.maxother = limit
    shortener.maxlist = shortener.maxtuple = shortener.maxdict = 6
    shortener.maxlevel = 3
    text = shortener.repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
