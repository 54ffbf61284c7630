"""Checks at the public boundary of the library (as stylegan2-ada's ``assert_shape`` and kornia's
``KORNIA_CHECK_SHAPE``): a tensor of the wrong shape fails at the call, with a message that names
the argument, the shape it needs and the shape it has, instead of an index error deep inside.

    sizes = check_shape(x, "face_conv: x", ("F", 16))
    check_shape(neighbors, "face_conv: neighbors", ("F", 9), sizes=sizes)   # the same F as x

A shape is a sequence of ints (that size), strings (a named size: every use of the name in one
``sizes`` must agree) and None (any size). Several shapes are alternatives, e.g. ``(B, V, 4)`` or
``(V, 4)``. ``dtype="float"`` or ``"int"`` also asks for a dtype family (a TypeError otherwise):

    sizes = check_shape(pos, "rasterize: pos", ("B", "V", 4), ("V", 4), dtype="float")

The checks read shapes and dtypes only: no device synchronisation, nothing that depends on the
values, so they cost microseconds and may stand at the top of every public function. NumPy arrays
(the geometry's) have :func:`check_array_shape`, the same shapes and message without a tensor, and
this module imports torch only when a tensor is checked (``mesh2tex.geometry`` stays torch-free).
"""

from __future__ import annotations

from typing import Sequence

Shape = Sequence[int | str | None]

# dtype families: name -> (test, how a message calls it)
_DTYPES = {
    "float": (lambda d: d.is_floating_point, "a floating-point"),
    "int": (lambda d: not d.is_floating_point and not d.is_complex and str(d) != "torch.bool", "an integer"),
    "bool": (lambda d: str(d) == "torch.bool", "a bool"),
}


def _text(shape: Shape) -> str:
    return "[" + ", ".join("*" if d is None else str(d) for d in shape) + "]"


def _matches(actual: tuple[int, ...], shape: Shape, sizes: dict[str, tuple[int, str]]) -> str | None:
    """None when ``actual`` fits ``shape`` (named sizes checked against ``sizes``), else why not."""
    if len(actual) != len(shape):
        return ""
    for have, want in zip(actual, shape):
        if isinstance(want, str):
            if want in sizes and sizes[want][0] != have:
                size, source = sizes[want]
                return f" ({want} = {size} from {source})"
        elif want is not None and want != have:
            return ""
    return None


def _fit(
    actual: tuple[int, ...], name: str, shapes: Sequence[Shape], sizes: dict[str, tuple[int, str]]
) -> dict[str, tuple[int, str]]:
    """``sizes`` with the named sizes ``actual`` fixed when it fits one of ``shapes``; ValueError naming ``name``
    otherwise."""
    reasons = []
    for shape in shapes:
        reason = _matches(actual, shape, sizes)
        if reason is None:
            for have, want in zip(actual, shape):
                if isinstance(want, str):
                    sizes.setdefault(want, (have, name.rpartition(": ")[2]))
            return sizes
        reasons.append(reason)
    expected = " or ".join(_text(s) + r for s, r in zip(shapes, reasons))
    raise ValueError(f"{name} must have shape {expected}, got {_text(actual)}")


def check_shape(
    tensor,
    name: str,
    *shapes: Shape,
    sizes: dict[str, tuple[int, str]] | None = None,
    dtype: str | None = None,
    optional: bool = False,
) -> dict[str, tuple[int, str]]:
    """Raise unless ``tensor`` is a tensor of one of ``shapes``; returns ``sizes`` with the named sizes it fixed.

    Args:
        tensor: the argument to check.
        name: how the message names it, e.g. ``"rasterize: pos"``.
        shapes: one or more alternative shapes (ints, size names, None for any size).
        sizes: {size name: (size, argument that fixed it)} shared by the checks of one call.
        dtype: None (any), "float" (any floating-point dtype), "int" (any integer dtype, not bool) or "bool".
        optional: None is accepted (an argument that may be left out), and fixes no size.
    Raises:
        TypeError: ``tensor`` is not a ``torch.Tensor``, or not of the ``dtype`` family.
        ValueError: its shape fits none of ``shapes``.
    """
    import torch

    sizes = {} if sizes is None else sizes
    if optional and tensor is None:
        return sizes
    if not isinstance(tensor, torch.Tensor):
        raise TypeError(
            f"{name} must be a torch.Tensor of shape {' or '.join(_text(s) for s in shapes)}, got "
            f"{type(tensor).__name__}"
        )
    if dtype is not None and not _DTYPES[dtype][0](tensor.dtype):
        raise TypeError(f"{name} must be {_DTYPES[dtype][1]} tensor, got {str(tensor.dtype).replace('torch.', '')}")
    return _fit(tuple(tensor.shape), name, shapes, sizes)


def check_array_shape(
    array, name: str, *shapes: Shape, sizes: dict[str, tuple[int, str]] | None = None, optional: bool = False
) -> dict[str, tuple[int, str]]:
    """:func:`check_shape` for a NumPy array (or anything :func:`numpy.shape` reads: a nested list, a
    tensor): ValueError naming ``name`` unless its shape fits one of ``shapes``. Converts nothing."""
    import numpy as np

    sizes = {} if sizes is None else sizes
    if optional and array is None:
        return sizes
    shape = getattr(array, "shape", None)
    return _fit(tuple(np.shape(array) if shape is None else shape), name, shapes, sizes)


def check_type(value, name: str, kind: type):
    """Raise TypeError unless ``value`` is a ``kind`` (e.g. a :class:`~mesh2tex.render.Raster`), naming the argument."""
    if not isinstance(value, kind):
        raise TypeError(f"{name} must be a {kind.__name__}, got {type(value).__name__}")
    return value


def check_array(value, name: str, *shapes: Shape, dtype=None):
    """``value`` (a numpy array, a tensor or a nested sequence) as a contiguous numpy array of ``dtype``
    (None: as it is), checked against ``shapes`` as :func:`check_shape` does; ValueError naming it otherwise."""
    import numpy as np
    import torch

    if isinstance(value, torch.Tensor):
        value = value.detach().cpu().numpy()
    array = np.ascontiguousarray(np.asarray(value), dtype=dtype)
    _fit(array.shape, name, shapes, {})
    return array
