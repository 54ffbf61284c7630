"""Shipped models: trained checkpoints a user names instead of a path (``--checkpoint chair``).

A model is a folder ``<models>/<name>/`` with one inference checkpoint per kind and a model card:

    generator.safetensors  kind "gan": the EMA generator only (group ``generator_ema``), float16
    pose.safetensors       kind "pose": the pose network (group ``net``), float16
    noc.safetensors        kind "noc": the NOC network (group ``net``), float16
    card.md, card.json     how it was made (world, commands, iterations, hardware, wall time) and its figures

``<models>`` is ``$MESH2TEX_MODELS`` when set, else the ``models/`` folder of the source tree
(next to the ``mesh2tex`` package). Loading a float16 state into a model's float32 parameters
(``load_state_dict``) casts it back.
"""

from __future__ import annotations

import os
from pathlib import Path

from mesh2tex.errors import UserError
from mesh2tex.io.checkpoint import load_checkpoint, save_checkpoint

MODEL_FILES = {"gan": "generator.safetensors", "pose": "pose.safetensors", "noc": "noc.safetensors"}
INFERENCE_GROUPS = {"gan": "generator_ema", "pose": "net", "noc": "net"}


def models_root() -> Path:
    """The folder that holds the shipped models."""
    env = os.environ.get("MESH2TEX_MODELS")
    return Path(env) if env else Path(__file__).resolve().parents[2] / "models"


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


def resolve_checkpoint(value: str | os.PathLike, kind: str) -> Path:
    """A checkpoint path as given, or the ``kind`` checkpoint of the shipped model named ``value``.

    Raises UserError for an unknown model name (listing the shipped ones) or a model without that kind.
    """
    if kind not in MODEL_FILES:
        raise ValueError(f"unknown checkpoint kind {kind!r}; expected one of {', '.join(MODEL_FILES)}")
    if not is_model_name(value):
        return Path(value)
    names = list_models()
    if str(value) not in names:
        shipped = ", ".join(names) if names else f"none in {models_root()}"
        raise UserError(f"{value}: no such checkpoint file or shipped model (shipped models: {shipped})")
    path = models_root() / str(value) / MODEL_FILES[kind]
    if not path.is_file():
        raise UserError(f"{path}: the shipped model '{value}' has no {kind} network")
    return path


def export_inference_checkpoint(source: str | os.PathLike, kind: str, target: str | os.PathLike, half: bool = True) -> dict:
    """Write the inference part of a training checkpoint: the ``INFERENCE_GROUPS[kind]`` weights
    (float16 when ``half``) and the metadata without RNG states. Returns the metadata written."""
    groups, meta = load_checkpoint(source, kind=kind)
    group = INFERENCE_GROUPS[kind]
    if group not in groups:
        raise UserError(f"{source}: no '{group}' weights in this {kind} checkpoint")
    kept = {k: v for k, v in meta.items() if k != "rng"}
    kept["exported_from"] = {"file": Path(source).name}
    return save_inference_checkpoint(target, kind, groups[group], kept, half)


def save_inference_checkpoint(target: str | os.PathLike, kind: str, state: dict, meta: dict, half: bool = True) -> dict:
    """Write one network's ``state`` (float16 when ``half``) as an inference checkpoint of ``kind``
    (group ``INFERENCE_GROUPS[kind]``) with ``meta``; returns the metadata written."""
    tensors = {name: (t.detach().half() if half and t.is_floating_point() else t.detach()) for name, t in state.items()}
    meta = {**meta, "dtype": "float16" if half else "float32"}
    save_checkpoint(target, {INFERENCE_GROUPS[kind]: tensors}, kind, meta)
    return meta



def load_nca(path: str | os.PathLike, device="cpu"):
    """A trained cellular automaton from a ``train nca`` checkpoint (training or exported).

    Returns (model :class:`mesh2tex.nn.nca.MeshNCA` in eval mode on ``device``, meta, exemplar
    (H, W, 3) uint8 or None). Raises UserError naming ``path`` for a missing, foreign or damaged file.
    """
    import torch

    from mesh2tex.config import config_from_dict
    from mesh2tex.nn.nca import MeshNCA, NCAConfig

    groups, meta = load_checkpoint(path, kind="nca")
    if "model" not in groups or "nca" not in meta:
        raise UserError(f"{path}: the nca checkpoint holds no automaton")
    try:
        cfg = config_from_dict(NCAConfig, meta["nca"], where=f"{path} nca")
    except ValueError as error:
        raise UserError(f"{path}: {error}") from None
    model = MeshNCA(cfg)
    try:
        model.load_state_dict({k: v.float() for k, v in groups["model"].items()})
    except RuntimeError as error:
        raise UserError(f"{path}: the automaton weights do not fit its config ({str(error).splitlines()[0]})") from None
    exemplar = groups.get("exemplar", {}).get("image")
    exemplar = None if exemplar is None else exemplar.permute(1, 2, 0).numpy()
    return model.to(device).eval(), meta, exemplar
