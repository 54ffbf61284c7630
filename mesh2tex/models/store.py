"""Every checkpoint kind in one place: the tensor groups and metadata keys each kind holds, and the
shipped models, trained checkpoints a user names instead of a path (``--checkpoint chair``); the
loaders of the trained networks are :mod:`mesh2tex.models.loading`.

Checkpoint kinds and their tensor groups (the file format itself is :mod:`mesh2tex.io.checkpoint`):

    gan    training: generator, generator_ema, d_field, d_proxy, loss, optim_g, optim_d; inference:
           generator_ema. Metadata: iteration, config (the 'train gan' config, with its camera),
           generator_config (what :func:`load_generator` builds), world_size.
    pose   the pose network (group ``net``, plus ``optim_opt`` while training); metadata: iteration,
    noc    config (the 'train pose|noc|mask' config, :class:`mesh2tex.nn.view_nets.ViewTrainConfig`).
    mask

A model is a folder ``<models>/<name>/`` with one inference checkpoint per kind and a model card:

    generator.safetensors  kind "gan": the EMA generator only (group ``generator_ema``), float16
    pose.safetensors       kind "pose": the pose network (group ``net``), float16
    noc.safetensors        kind "noc": the NOC network (group ``net``), float16
    mask.safetensors       kind "mask": the mask network (group ``net``), float16; optional (without it a
                           photo without a mask is cut out by GrabCut alone)
    card.md, card.json     how it was made (world, commands, iterations, hardware, wall time) and its figures

``<models>`` is ``$MESH2TEX_MODELS`` when set, else this package's own folder ``mesh2tex/models/`` (package
data: the shipped models travel in the wheel, so they are there after any install). Loading a float16 state into a
model's float32 parameters (``load_state_dict``) casts it back.
"""

from __future__ import annotations

import os
from pathlib import Path

from mesh2tex.errors import InputError
from mesh2tex.io.checkpoint import load_checkpoint, save_checkpoint

# Tensor groups of the 'gan' kind.
GENERATOR, GENERATOR_EMA, D_FIELD, D_PROXY, GAN_LOSS = "generator", "generator_ema", "d_field", "d_proxy", "loss"
# Metadata key of the 'gan' kind with the GeneratorConfig that load_generator builds.
GENERATOR_CONFIG = "generator_config"
# Metadata key of the 'gan' kind with the hierarchy its training shapes were prepared with: {"faces", "levels"}.
HIERARCHY = "hierarchy"
# What a raw mesh is prepared with for a generator whose checkpoint names no hierarchy (written before it did).
DEFAULT_HIERARCHY_FACES = 6144
# Tensor group of the 'pose' and 'noc' kinds.
VIEW_NET = "net"
MODEL_FILES = {
    "gan": "generator.safetensors",
    "pose": "pose.safetensors",
    "noc": "noc.safetensors",
    "mask": "mask.safetensors",
}
INFERENCE_GROUPS = {"gan": GENERATOR_EMA, "pose": VIEW_NET, "noc": VIEW_NET, "mask": VIEW_NET}


def models_root() -> Path:
    """The folder that holds the shipped models."""
    env = os.environ.get("MESH2TEX_MODELS")
    return Path(env) if env else Path(__file__).resolve().parent


def list_models() -> list[str]:
    """Names of the shipped models (folders with a generator checkpoint), sorted."""
    root = models_root()
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if (p / MODEL_FILES["gan"]).is_file())


def is_model_name(value: str | os.PathLike) -> bool:
    """True for a bare name (no folder, no suffix) that is not an existing file: ``chair``, ``car``."""
    text = str(value)
    return bool(text) and os.sep not in text and "/" not in text and "." not in text and not Path(text).exists()


def model_has(name: str, kind: str) -> bool:
    """Whether the shipped model ``name`` holds a ``kind`` network (the mask network is optional)."""
    return (models_root() / name / MODEL_FILES[kind]).is_file()


def resolve_checkpoint(value: str | os.PathLike, kind: str) -> Path:
    """A checkpoint path as given, or the ``kind`` checkpoint of the shipped model named ``value``.

    Raises InputError for an unknown model name (listing the shipped ones) or a model without that kind.
    """
    if kind not in MODEL_FILES:
        raise ValueError(f"unknown checkpoint kind {kind!r}; expected one of {', '.join(MODEL_FILES)}")
    if not is_model_name(value):
        return Path(value)
    names = list_models()
    if str(value) not in names:
        shipped = ", ".join(names) if names else f"none in {models_root()}"
        raise InputError(f"{value}: no such checkpoint file or shipped model (shipped models: {shipped})")
    path = models_root() / str(value) / MODEL_FILES[kind]
    if not path.is_file():
        raise InputError(f"{path}: the shipped model '{value}' has no {kind} network")
    return path


# What a training checkpoint's metadata holds only to resume (check_training_checkpoint looks for them).
TRAINING_ONLY_META = ("rng", "optimizers")


def export_inference_checkpoint(
    source: str | os.PathLike, kind: str, target: str | os.PathLike, half: bool = True
) -> dict:
    """Write the inference part of a training checkpoint: the ``INFERENCE_GROUPS[kind]`` weights
    (float16 when ``half``) and the metadata without the training state (RNG states, optimizer
    settings), so that the file is read as an inference checkpoint. Returns the metadata written."""
    groups, meta = load_checkpoint(source, kind=kind)
    group = INFERENCE_GROUPS[kind]
    if group not in groups:
        raise InputError(f"{source}: no '{group}' weights in this {kind} checkpoint")
    kept = {k: v for k, v in meta.items() if k not in TRAINING_ONLY_META}
    kept["exported_from"] = {"file": Path(source).name}
    return save_inference_checkpoint(target, kind, groups[group], kept, half)


def save_inference_checkpoint(target: str | os.PathLike, kind: str, state: dict, meta: dict, half: bool = True) -> dict:
    """Write one network's ``state`` (float16 when ``half``) as an inference checkpoint of ``kind``
    (group ``INFERENCE_GROUPS[kind]``) with ``meta``; returns the metadata written."""
    tensors = {name: (t.detach().half() if half and t.is_floating_point() else t.detach()) for name, t in state.items()}
    meta = {**meta, "dtype": "float16" if half else "float32"}
    save_checkpoint(target, {INFERENCE_GROUPS[kind]: tensors}, kind, meta)
    return meta
