"""The finished transfers of protocol runs kept in their output folder (:class:`TransferCache`), so
that an interrupted run resumes and a larger run redoes none of them."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import torch

from mesh2tex.errors import InputError
from mesh2tex.io.atomic import atomic_path, write_json
from mesh2tex.nn.generator import FaceTexture


class TransferCache:
    """Finished transfers of protocol runs into one folder: an interrupted run resumes where it stopped,
    and a run with more queries or ablations redoes none of the transfers already made.

    ``DIR/transfers/<protocol>/<ablation>/<query>.npz`` holds the result of one transfer, the
    synthesis output: face features [F_0, C] and face colours [F_0, 3] (float32; with the unchanged
    psi they are the whole texture, so
    the evaluation can be redone with other metrics, views or lighting without redoing the transfer),
    and its row (JSON: last losses, seconds); ``DIR/transfers/settings.json`` what they were made
    with: every setting that changes a transfer (not the choice of protocols, ablations or number of
    queries) and the digests of the checkpoints. Transfers made with other settings are never mixed
    in: the run is refused, or with ``--overwrite`` they are discarded. Because each transfer is its
    own file, a long run can be split across processes into the same folder (``--ablations full``
    in one, ``--ablations no_noc`` in another...); one more run with every ablation then only builds
    the tables.
    """

    def __init__(self, out: Path, fingerprint: dict, overwrite: bool = False):
        self.root = out / "transfers"
        settings = self.root / "settings.json"
        if settings.is_file() and _comparable(json.loads(settings.read_text())) != _comparable(fingerprint):
            if not overwrite:
                raise InputError(
                    f"{out}: holds transfers made with other settings or checkpoints ({settings}); "
                    "use the same settings to reuse them, or pass --overwrite to discard them"
                )
            shutil.rmtree(self.root)
        if not settings.is_file():
            write_json(settings, fingerprint)

    def _path(self, protocol: str, ablation: str, query: str) -> Path:
        return self.root / protocol / ablation / f"{query}.npz"

    def load(self, protocol: str, ablation: str, query: str) -> tuple[FaceTexture, dict] | None:
        """(the synthesis output, row) of a finished transfer, or None (also for a file of an older
        layout, which kept only a render or only the face features: that transfer is made again)."""
        path = self._path(protocol, ablation, query)
        if not path.is_file():
            return None
        with np.load(path, allow_pickle=False) as data:
            if "field_features" not in data or "face_rgb" not in data:
                return None
            texture = FaceTexture(
                field_features=torch.from_numpy(data["field_features"]), face_rgb=torch.from_numpy(data["face_rgb"])
            )
            return texture, json.loads(str(data["row"]))

    def save(self, protocol: str, ablation: str, query: str, texture: FaceTexture, row: dict) -> None:
        with atomic_path(self._path(protocol, ablation, query)) as tmp:
            np.savez(
                tmp,
                field_features=texture.field_features.detach().float().cpu().numpy(),
                face_rgb=texture.face_rgb.detach().float().cpu().numpy(),
                row=np.array(json.dumps(row)),
            )


def _comparable(fingerprint: dict) -> dict:
    """A fingerprint without ``settings.transfer`` (the TransferConfig fields a config set, beside the former
    ones), which ``settings.transfer_config`` holds resolved: a folder made with a field set to its default matches."""
    settings = {k: v for k, v in fingerprint.get("settings", {}).items() if k != "transfer"}
    return {**fingerprint, "settings": settings}
