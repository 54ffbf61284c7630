"""The settings of ``mesh2tex app`` (:class:`AppConfig`, read from ``--config`` and the flags by
:func:`mesh2tex.app.server.build_config`): where it serves, the bounds of uploads and jobs, and the flags of
the commands its page runs."""

from __future__ import annotations

import shlex
from dataclasses import dataclass

from mesh2tex.config import check_fields
from mesh2tex.options import DEVICES

LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")
# flags the page sets itself in every command it runs
OWN_FLAGS = ("--out", "--device", "--mesh", "--checkpoint", "--image", "--exemplar", "--seeds", "--seed", "--overwrite")


@dataclass
class AppConfig:
    host: str = "127.0.0.1"  # address to serve on: 127.0.0.1 is this machine only; 0.0.0.0 is every network it is on
    port: int = 7860  # port to serve on (0: a free one, printed)
    device: str = "auto"  # where the jobs run: auto, cpu or cuda
    jobs: int = 1  # jobs that run at once; later ones wait their turn (each command takes the cores it can)
    max_seeds: int = 8  # most seeds one Generate paints (shown as a gallery)
    max_mesh_mb: float = 50.0  # largest mesh upload, megabytes
    max_photo_mb: float = 20.0  # largest photo, exemplar image or NCA model upload, megabytes
    job_timeout: float = 3600.0  # a job running longer than this many seconds is stopped
    keep_minutes: float = 30.0  # a visitor's files are deleted this long after the page's last request or its closing
    generate_flags: str = "--views 1"  # flags of every 'infer generate' the page runs (a view per seed: its thumbnail)
    transfer_flags: str = ""  # flags of every 'infer transfer' the page runs
    quick_transfer_flags: str = "--latent-iters 20 --refine-iters 30"  # the page's quick budget of a transfer
    synthesize_flags: str = ""  # flags of every 'infer synthesize' (a texture after an exemplar image)
    quick_synthesize_flags: str = "--iters 100 --texture-size 256"  # the page's quick budget of an exemplar's texture
    nca_flags: str = ""  # flags of every 'infer nca' (a texture grown by an uploaded NCA model)

    def __post_init__(self):
        check_fields(
            self,
            at_least={"port": 0, "jobs": 1, "max_seeds": 1},
            positive=("max_mesh_mb", "max_photo_mb", "job_timeout", "keep_minutes"),
        )
        if self.port > 65535:
            raise ValueError(f"port {self.port}: must be at most 65535")
        if self.device not in DEVICES:
            raise ValueError(f"device {self.device!r}: choose one of {', '.join(DEVICES)}")
        for name in (
            "generate_flags",
            "transfer_flags",
            "quick_transfer_flags",
            "synthesize_flags",
            "quick_synthesize_flags",
            "nca_flags",
        ):
            own = [word for word in flags(getattr(self, name), name) if word.split("=")[0] in OWN_FLAGS]
            if own:
                raise ValueError(f"{name}: {own[0].split('=')[0]} is set by the page itself")


def flags(text: str, name: str = "flags") -> list[str]:
    """The words of a flags field, split as a shell would."""
    try:
        return shlex.split(text)
    except ValueError as error:
        raise ValueError(f"{name} {text!r}: {error}") from None
