"""Checkpoints without pickle: tensors in safetensors, everything else as JSON in its metadata.

A checkpoint is one ``.safetensors`` file. Tensor names are ``<group>/<name>`` (for example
``generator/mapping.fc0.weight`` or ``optim_g/state.3.exp_avg``); the JSON metadata holds the
format version, the kind of checkpoint (``gan``, ``pose``, ``noc`` ...), the resolved config and
any plain-JSON state (iteration, optimizer hyperparameters, RNG states encoded as tensors).
Writes are atomic, so a kill during a save never spoils the previous checkpoint.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file
from torch import nn

from mesh2tex.errors import InputError
from mesh2tex.io.atomic import atomic_path

CHECKPOINT_FORMAT = 1
_META_KEY = "mesh2tex"


def flatten_state(groups: dict[str, dict[str, torch.Tensor]]) -> dict[str, torch.Tensor]:
    """{group: {name: tensor}} -> {"group/name": contiguous CPU tensor}."""
    flat = {}
    for group, tensors in groups.items():
        for name, tensor in tensors.items():
            flat[f"{group}/{name}"] = tensor.detach().to("cpu").contiguous()
    return flat


def unflatten_state(flat: dict[str, torch.Tensor]) -> dict[str, dict[str, torch.Tensor]]:
    """Inverse of :func:`flatten_state`."""
    groups: dict[str, dict[str, torch.Tensor]] = {}
    for key, tensor in flat.items():
        group, _, name = key.partition("/")
        groups.setdefault(group, {})[name] = tensor
    return groups


def save_checkpoint(
    path: str | os.PathLike, groups: dict[str, dict[str, torch.Tensor]], kind: str, meta: dict[str, Any]
) -> None:
    """Atomically write tensor ``groups`` and JSON-serialisable ``meta`` to ``path`` (.safetensors)."""
    header = {"format": CHECKPOINT_FORMAT, "kind": kind, "meta": meta}
    flat = flatten_state(groups)
    # safetensors refuses tensors that share memory; clone those that do.
    seen: dict[int, str] = {}
    for key, tensor in flat.items():
        ptr = tensor.untyped_storage().data_ptr() if tensor.numel() else -1
        if ptr in seen:
            flat[key] = tensor.clone()
        elif ptr != -1:
            seen[ptr] = key
    with atomic_path(path, suffix=".safetensors") as tmp:
        save_file(flat, str(tmp), metadata={_META_KEY: json.dumps(header)})


def checkpoint_digest(path: str | os.PathLike, what: str = "checkpoint") -> str:
    """SHA-256 prefix (16 hex digits) of a file's bytes: the identity of a checkpoint wherever it lies
    (a moved one keeps it, a retrained one does not). InputError naming ``what`` when it is missing."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: {what} not found")
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def check_header(header: Any) -> dict[str, Any]:
    """The schema of a checkpoint's mesh2tex header: a mapping with an integer ``format``, a string
    ``kind`` and a mapping ``meta``; ValueError saying what is wrong."""
    if not isinstance(header, dict):
        raise ValueError(f"its header is a {type(header).__name__}, not a mapping")
    if not isinstance(header.get("format"), int) or isinstance(header.get("format"), bool):
        raise ValueError("its header has no format number")
    if not isinstance(header.get("kind"), str):
        raise ValueError("its header has no kind")
    if not isinstance(header.get("meta"), dict):
        raise ValueError("its header has no 'meta' mapping")
    return header


def read_checkpoint_meta(path: str | os.PathLike) -> dict[str, Any]:
    """The JSON header ({format, kind, meta}) of a checkpoint, without loading its tensors; InputError
    for anything that is not a checkpoint this module wrote (checked against :func:`check_header`)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: checkpoint not found")
    try:
        with open(path, "rb") as handle:
            size = int.from_bytes(handle.read(8), "little")
            if size <= 0 or size > 100_000_000:
                raise ValueError("bad header size")
            header = json.loads(handle.read(size))
        if not isinstance(header, dict):
            raise ValueError(f"the safetensors header is a {type(header).__name__}, not a mapping")
        meta = header.get("__metadata__", {})
        if not isinstance(meta, dict) or not isinstance(meta.get(_META_KEY), str):
            raise ValueError("no mesh2tex metadata")
        return check_header(json.loads(meta[_META_KEY]))
    except (ValueError, UnicodeDecodeError, RecursionError, OSError) as error:
        reason = (
            "nested too deeply"
            if isinstance(error, RecursionError)
            else (str(error) if type(error) is ValueError else error.__class__.__name__)
        )
        raise InputError(f"{path}: not a mesh2tex checkpoint ({reason})") from None


def meta_mapping(meta: dict[str, Any], key: str, path: str | os.PathLike) -> dict[str, Any]:
    """``meta[key]``, a mapping; InputError naming ``path`` when the checkpoint has none."""
    value = meta.get(key)
    if not isinstance(value, dict):
        raise InputError(f"{path}: not a usable checkpoint (its metadata has no '{key}' mapping)")
    return value


def load_checkpoint(
    path: str | os.PathLike, kind: str | None = None, map_location: str = "cpu"
) -> tuple[dict[str, dict[str, torch.Tensor]], dict[str, Any]]:
    """Load a checkpoint; returns (tensor groups, meta). ``kind`` checks the checkpoint's kind."""
    header = read_checkpoint_meta(path)
    if header.get("format") != CHECKPOINT_FORMAT:
        raise InputError(
            f"{path}: checkpoint format {header.get('format')} is not supported (expected {CHECKPOINT_FORMAT})"
        )
    if kind is not None and header.get("kind") != kind:
        raise InputError(f"{path}: this is a '{header.get('kind')}' checkpoint, expected a '{kind}' checkpoint")
    try:
        flat = load_file(str(path), device=map_location)
    except (SafetensorError, OSError) as error:
        raise InputError(f"{path}: damaged checkpoint ({error})") from None
    return unflatten_state(flat), header["meta"]


def check_training_checkpoint(path: str | os.PathLike, kind: str) -> dict[str, Any]:
    """The header of a training checkpoint of ``kind`` (what :func:`save_training_state` writes), read
    without loading its tensors; a one-line InputError naming ``path`` for another kind, an inference
    checkpoint (a snapshot or shipped model: weights without optimizer state) or another format."""
    header = read_checkpoint_meta(path)
    if header["format"] != CHECKPOINT_FORMAT:
        raise InputError(
            f"{path}: checkpoint format {header['format']} is not supported (expected {CHECKPOINT_FORMAT})"
        )
    if header["kind"] != kind:
        raise InputError(f"{path}: this is a '{header['kind']}' checkpoint, expected a '{kind}' training checkpoint")
    meta = header["meta"]
    if not isinstance(meta.get("optimizers"), dict):
        weights = f"{meta['dtype']} " if isinstance(meta.get("dtype"), str) else ""
        raise InputError(
            f"{path}: an inference checkpoint ({weights}weights without optimizer state, such as a snapshot or a "
            f"shipped model), not a training checkpoint; a run starts only from another run's checkpoint.safetensors"
        )
    if not isinstance(meta.get("iteration"), int) or not isinstance(meta.get("rng"), list):
        raise InputError(f"{path}: not a usable training state (no iteration or RNG states)")
    return header


# ------------------------------------------------------------------------------------- state codecs
def optimizer_to_state(opt: torch.optim.Optimizer) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """Optimizer -> (tensors, JSON meta): per-parameter state tensors and the param groups."""
    sd = opt.state_dict()
    tensors, scalars = {}, {}
    for index, state in sd["state"].items():
        for key, value in state.items():
            if torch.is_tensor(value):
                tensors[f"{index}.{key}"] = value
            else:
                scalars[f"{index}.{key}"] = value
    return tensors, {"param_groups": sd["param_groups"], "scalars": scalars}


def optimizer_from_state(opt: torch.optim.Optimizer, tensors: dict[str, torch.Tensor], meta: dict[str, Any]) -> None:
    """Inverse of :func:`optimizer_to_state`."""
    state: dict[int, dict[str, Any]] = {}
    for name, value in list(tensors.items()) + list(meta["scalars"].items()):
        index, _, key = name.partition(".")
        state.setdefault(int(index), {})[key] = value
    groups = []
    for group in meta["param_groups"]:
        group = dict(group)
        if "betas" in group:
            group["betas"] = tuple(group["betas"])
        groups.append(group)
    opt.load_state_dict({"state": state, "param_groups": groups})


# ------------------------------------------------------------------------------ training states
def save_training_state(
    path: Path,
    kind: str,
    modules: dict[str, nn.Module],
    optimizers: dict[str, torch.optim.Optimizer],
    extra_tensors: dict[str, dict[str, torch.Tensor]],
    meta: dict[str, Any],
    rng_states: list[dict[str, Any]],
) -> None:
    """Write modules, optimizers, extra tensor groups, per-process RNG states and ``meta`` atomically."""
    groups: dict[str, dict[str, torch.Tensor]] = {name: m.state_dict() for name, m in modules.items()}
    optim_meta = {}
    for name, opt in optimizers.items():
        tensors, optim_meta[name] = optimizer_to_state(opt)
        groups[f"optim_{name}"] = tensors
    groups.update(extra_tensors)
    meta = {**meta, "optimizers": optim_meta, "rng": rng_states}
    save_checkpoint(path, groups, kind=kind, meta=meta)


def _rng_state_like(state: Any) -> bool:
    """Whether ``state`` has the form of :func:`mesh2tex.runtime.rng_to_state`'s (its values are not checked)."""
    return (
        isinstance(state, dict)
        and isinstance(state.get("torch"), list)
        and isinstance(state.get("cuda"), list)
        and isinstance(state.get("numpy"), list)
        and len(state["numpy"]) == 5
        and isinstance(state.get("python"), list)
        and len(state["python"]) == 3
    )


def load_training_state(
    path: Path,
    kind: str,
    modules: dict[str, nn.Module],
    optimizers: dict[str, torch.optim.Optimizer],
    device: torch.device,
) -> tuple[dict[str, dict[str, torch.Tensor]], dict[str, Any]]:
    """Load what :func:`save_training_state` wrote into ``modules`` and ``optimizers``; returns
    (all tensor groups, meta) for the caller's extra state. RNG states are not applied here."""
    groups, meta = load_checkpoint(path, kind=kind)
    for name, module in modules.items():
        if name not in groups:
            raise InputError(f"{path}: checkpoint has no '{name}' weights")
        try:
            module.load_state_dict(groups[name])
        except RuntimeError as error:
            raise InputError(
                f"{path}: '{name}' weights do not fit this config ({str(error).splitlines()[0]})"
            ) from None
        module.to(device)
    saved = meta_mapping(meta, "optimizers", path)
    if (
        not isinstance(meta.get("rng"), list)
        or not isinstance(meta.get("iteration"), int)
        or not all(map(_rng_state_like, meta["rng"]))
    ):
        raise InputError(f"{path}: not a usable training state (no iteration, or RNG states of another form)")
    for name, opt in optimizers.items():
        state = meta_mapping(saved, name, path)  # outside the try: its InputError is a ValueError with its own message
        try:
            optimizer_from_state(opt, groups.get(f"optim_{name}", {}), state)
        except (KeyError, ValueError, TypeError, AttributeError) as error:
            raise InputError(f"{path}: the '{name}' optimizer state does not fit this config ({error})") from None
    return groups, meta
