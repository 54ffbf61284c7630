"""Loading a trained network of any kind: the generator as a :class:`TrainedGenerator` record (the
network and everything inference needs from its checkpoint: the camera and lighting it was trained
with, the hierarchy a raw mesh is prepared with, where it came from), the pose, NOC and mask
networks with their config, the cellular automaton with its exemplar.

No caller parses a checkpoint's metadata: what a command needs is a field of the record.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from mesh2tex.config import config_from_dict
from mesh2tex.errors import InputError, note
from mesh2tex.io.checkpoint import load_checkpoint, meta_mapping
from mesh2tex.nn.generator import GeneratorConfig, TextureGenerator
from mesh2tex.nn.nca import MeshNCA, NCAConfig
from mesh2tex.nn.view_nets import ViewTrainConfig, build_network
from mesh2tex.render.cameras import CameraConfig, NCACameraConfig

from .store import DEFAULT_HIERARCHY_FACES, GENERATOR_CONFIG, GENERATOR_EMA, HIERARCHY, VIEW_NET, resolve_checkpoint


@dataclass(frozen=True)
class TrainedGenerator:
    """A trained texture generator and what inference needs from its checkpoint.

    network: the EMA generator in eval mode without gradients; camera: the orbit camera it was trained
    with (distance, field of view); lit: whether its training renders were shaded; hierarchy_faces:
    the finest quad count of its training shapes' hierarchy (what a raw mesh is prepared with),
    hierarchy_recorded: False for a checkpoint written before it was recorded (then
    :data:`DEFAULT_HIERARCHY_FACES`); resolution: the side of its training renders (None if the checkpoint
    does not say); source: the checkpoint file; iteration: the training iteration
    it was taken at (None if unknown); meta: the checkpoint's metadata as written, for provenance
    (a report's lineage), never for settings.
    """

    network: TextureGenerator
    camera: CameraConfig
    lit: bool
    hierarchy_faces: int
    hierarchy_recorded: bool
    source: Path
    resolution: int | None = None
    iteration: int | None = None
    meta: dict = field(default_factory=dict, repr=False)

    def face_count(self, requested: int = 0) -> int:
        """The finest quad count a raw mesh is prepared with: ``requested`` when given (> 0; with a note
        when it differs from the model's), else the model's own hierarchy."""
        trained = self.hierarchy_faces
        if requested < 0:
            raise InputError(f"--faces {requested}: must be positive (or 0: the hierarchy the model was trained on)")
        if requested and self.hierarchy_recorded and requested != trained:
            note(
                f"--faces {requested}: the model learnt on {trained}-quad hierarchies; the texture's features will "
                f"come out at about {(trained / requested) ** 0.5:.2g}x their learnt size"
            )
        if not requested and not self.hierarchy_recorded:
            note(
                "the checkpoint does not record the hierarchy its shapes were prepared with; preparing with "
                f"{trained} quads (--faces to change)"
            )
        return requested or trained


def load_generator(path: str | os.PathLike, device: torch.device | str = "cpu") -> TrainedGenerator:
    """The trained generator of a GAN checkpoint (a path, or a shipped model's name such as ``chair``)."""
    path = resolve_checkpoint(path, "gan")
    groups, meta = load_checkpoint(path, kind="gan")
    saved = dict(meta_mapping(meta, GENERATOR_CONFIG, path))
    saved.setdefault("field_residual", False)  # written before psi became a residual on the proxy colours
    cfg = config_from_dict(GeneratorConfig, saved, f"{path}: {GENERATOR_CONFIG}")
    generator = TextureGenerator(cfg)
    try:
        generator.load_state_dict(groups[GENERATOR_EMA])
    except (KeyError, RuntimeError) as error:
        raise InputError(f"{path}: generator weights missing or damaged ({str(error).splitlines()[0]})") from None
    faces, recorded = _hierarchy(meta)
    iteration = meta.get("iteration")
    resolution = meta.get("config", {}).get("resolution") if isinstance(meta.get("config"), dict) else None
    return TrainedGenerator(
        network=generator.to(device).eval().requires_grad_(False),
        camera=_camera(meta, path),
        lit=_trained_lit(meta),
        hierarchy_faces=faces,
        hierarchy_recorded=recorded,
        source=Path(path),
        resolution=resolution if isinstance(resolution, int) else None,
        iteration=iteration if isinstance(iteration, int) else None,
        meta=meta,
    )


def shape_hierarchy(shapes) -> dict:
    """{"faces": requested finest quads, "levels": levels} of prepared shapes (the first one's record:
    a training set is prepared with one setting): what a GAN checkpoint records under ``HIERARCHY``."""
    first = shapes[0]
    targets = first.metadata.get("targets") or [len(first.quads[0])]
    return {"faces": int(targets[0]), "levels": int(first.num_levels)}


def _hierarchy(meta: dict) -> tuple[int, bool]:
    recorded = meta.get(HIERARCHY)
    if isinstance(recorded, dict) and isinstance(recorded.get("faces"), int) and recorded["faces"] > 0:
        return recorded["faces"], True
    return DEFAULT_HIERARCHY_FACES, False


def _trained_lit(meta: dict) -> bool:
    # runs from before the light prior have no 'lighting' and were unlit
    return bool(meta.get("config", {}).get("lighting", {}).get("enabled", False))


def _camera(meta: dict, path: Path) -> CameraConfig:
    # config.camera of the 'train gan' config; CameraConfig's defaults where it has none
    config = meta.get("config", {})
    camera = config.get("camera", {}) if isinstance(config, dict) else {}
    camera = camera if isinstance(camera, dict) else {}
    default = CameraConfig()
    try:
        return CameraConfig(
            distance=float(camera.get("distance", default.distance)), fov=float(camera.get("fov", default.fov))
        )
    except (TypeError, ValueError) as error:
        raise InputError(f"{path}: the checkpoint's config.camera is not usable ({error})") from None


def load_view_network(
    path: str | os.PathLike, kind: str, device: torch.device | str = "cpu"
) -> tuple[torch.nn.Module, ViewTrainConfig]:
    """A trained pose, NOC or mask network (eval mode) and its config, from a ``train pose|noc|mask`` checkpoint
    (a path, or a shipped model's name such as ``chair``)."""
    path = resolve_checkpoint(path, kind)
    groups, meta = load_checkpoint(path, kind=kind)
    cfg = config_from_dict(ViewTrainConfig, meta_mapping(meta, "config", path), where=str(path))
    net = build_network(kind, cfg)
    try:
        net.load_state_dict(groups[VIEW_NET])
    except (KeyError, RuntimeError) as error:
        raise InputError(f"{path}: the {kind} weights do not fit its config ({str(error).splitlines()[0]})") from None
    return net.to(device).eval(), cfg


class TrainedAutomaton(NamedTuple):
    """A trained cellular automaton and what inference needs from its checkpoint (it unpacks as
    ``(network, meta, exemplar)``).

    network: the :class:`mesh2tex.nn.nca.MeshNCA` in eval mode; meta: the checkpoint's metadata, for
    provenance; exemplar: (H, W, 3) uint8 the image it was trained on, or None.
    """

    network: MeshNCA
    meta: dict
    exemplar: np.ndarray | None

    @property
    def camera(self) -> NCACameraConfig:
        """The cameras it was trained with (``config.camera``; the defaults where the checkpoint has none)."""
        camera = self.meta.get("config", {}).get("camera", {}) if isinstance(self.meta.get("config"), dict) else {}
        return config_from_dict(
            NCACameraConfig, camera if isinstance(camera, dict) else {}, where="the checkpoint's config.camera"
        )

    @property
    def vgg_depth(self) -> int:
        """The VGG19 style layers its loss used (``config.vgg_depth``, 4 when not recorded)."""
        return int(self.meta.get("config", {}).get("vgg_depth", 4))

    @property
    def cell_spacing(self) -> float:
        """The mean edge length of its training cell mesh in the unit ball (0: not recorded)."""
        return float(self.meta.get("cell_spacing", 0.0))

    @property
    def lineage(self) -> str | None:
        """The id its family of models shares (a model trained with ``--parent`` keeps its parent's)."""
        return self.meta.get("lineage")


def load_nca(path: str | os.PathLike, device="cpu") -> TrainedAutomaton:
    """A trained cellular automaton from a ``train nca`` checkpoint (training or exported).

    Raises InputError naming ``path`` for a missing, foreign or damaged file.
    """
    groups, meta = load_checkpoint(path, kind="nca")
    if "model" not in groups or "nca" not in meta:
        raise InputError(f"{path}: the nca checkpoint holds no automaton")
    cfg = config_from_dict(NCAConfig, meta["nca"], where=f"{path} nca")  # its errors name the file
    model = MeshNCA(cfg)
    try:
        model.load_state_dict({k: v.float() for k, v in groups["model"].items()})
    except RuntimeError as error:
        raise InputError(
            f"{path}: the automaton weights do not fit its config ({str(error).splitlines()[0]})"
        ) from None
    exemplar = groups.get("exemplar", {}).get("image")
    exemplar = None if exemplar is None else exemplar.permute(1, 2, 0).numpy()
    return TrainedAutomaton(model.to(device).eval(), meta, exemplar)
