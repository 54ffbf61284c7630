"""The paper's protocols (``mesh2tex evaluate --protocols``): their settings, checked once; what of them
fingerprints a finished transfer (:func:`cache_settings`); and the inputs one run shares
(:class:`ProtocolInputs`). The protocols themselves: :mod:`mesh2tex.evaluation.protocols`."""

from __future__ import annotations

import typing
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

import torch

from mesh2tex.errors import InputError
from mesh2tex.evaluation.cache import TransferCache
from mesh2tex.evaluation.report import BASELINES, EXTRA_METHODS, PROTOCOLS
from mesh2tex.evaluation.world import World
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.metrics.evaluate import EvaluateConfig
from mesh2tex.render.settings import LIGHTING
from mesh2tex.transfer import ABLATIONS, TransferConfig

# TransferConfig fields every transfer takes from the protocol's own fields of the same name, and those the ablations
# set.
SHARED = ("resolution", "seed", "device", "vgg_weights")
ABLATED = ("use_noc", "use_patches", "refine")
# TransferConfig and EvaluateConfig fields that were ProtocolConfig's own before it nested them.
FORMER_FIELDS = ("latent_iters", "refine_iters", "patch_size", "scales", "patch_scales", "pose_search")
FORMER_EVALUATE_FIELDS = ("features", "kid_subsets")


# TransferConfig fields that change no transfer (the automaton baseline's fit, the GLB's image format): left out of the
# transfer cache's fingerprint, so that setting them reuses the cached transfers.
NOT_TRANSFER = ("automaton", "texture_format")


@dataclass
class ProtocolConfig:
    protocols: list[str] = field(default_factory=lambda: list(PROTOCOLS))  # which protocols to run
    ablations: list[str] = field(default_factory=lambda: list(ABLATIONS))  # which ablations of each transfer protocol
    queries: int = 0  # query photos used (first K in the world's order; 0: all)
    resolution: int = 64  # side of the photo crops, renders and set-metric images
    baselines: list[str] = field(default_factory=lambda: list(BASELINES))  # simple methods judged beside the transfers
    lighting: str = "photo"  # render every method with the photo's light ('photo') or unlit, as albedo ('albedo')
    unseen_views: int = 4  # views the photo does not show, evenly spaced in azimuth after the photo's
    lowpass_sigma: float = 3.0  # Gaussian blur of the low-pass PSNR, in pixels of the world's photos
    latents: int = 4  # unconditional: random latents per held-out shape
    views: int = 6  # unconditional: orbit views per latent (paper: 6)
    seed: int = 0  # seed of the transfers, the unconditional latents and the set metrics
    device: str = "auto"  # auto, cpu or cuda
    vgg_weights: str = ""  # VGG19 ImageNet weights for the style losses ('' looks in $TORCH_HOME)
    inception_weights: str = ""  # Inception-v3 weights for KID/FID ('' looks in $TORCH_HOME)
    # Every transfer's settings, which the ablations change; its resolution, seed, device and vgg_weights are the fields
    # above. 2 style scales, the patch loss's the same: 32 px patches keep a 16 px coarsest level (paper: 3
    # scales, 64 px
    # patches in larger crops).
    transfer: TransferConfig = field(default_factory=lambda: TransferConfig(resolution=64, scales=2, patch_scales=0))
    # The unconditional protocol's set metrics (KID/FID features, KID subsets, SWD sampling); its resolution and
    # seed are
    # the fields above.
    evaluate: EvaluateConfig = field(default_factory=lambda: EvaluateConfig(resolution=64))
    # The ``automaton`` method (when --baselines asks for it) is fitted with the transfer's losses and settings and its
    # ``transfer.automaton`` section.

    # Keys of older protocol configs that now live under ``transfer`` (named by the unknown-key error).
    MOVED_KEYS: typing.ClassVar[dict[str, str]] = (
        {name: f"transfer.{name}" for name in FORMER_FIELDS}
        | {name: f"evaluate.{name}" for name in FORMER_EVALUATE_FIELDS}
        | {"automaton": "transfer.automaton"}
    )

    def __post_init__(self):
        unknown = (
            [p for p in self.protocols if p not in PROTOCOLS]
            + [a for a in self.ablations if a not in ABLATIONS]
            + [b for b in self.baselines if b not in (*BASELINES, *EXTRA_METHODS)]
        )
        if unknown:
            raise InputError(
                f"unknown protocol, ablation or baseline {', '.join(unknown)}; protocols: {', '.join(PROTOCOLS)}; "
                f"ablations: {', '.join(ABLATIONS)}; baselines: {', '.join((*BASELINES, *EXTRA_METHODS))}"
            )
        if self.lighting not in LIGHTING:
            raise InputError(f"lighting {self.lighting!r}: must be one of {', '.join(LIGHTING)}")
        if not 0 <= self.unseen_views <= 35 or self.lowpass_sigma < 0:
            raise InputError(
                f"unseen_views {self.unseen_views}, lowpass_sigma {self.lowpass_sigma}: need 0-35 unseen views and a "
                "sigma >= 0"
            )
        if self.resolution < 32:
            raise InputError(f"--resolution {self.resolution}: must be at least 32")
        self.transfer = self._shared_into("transfer", SHARED)
        ablated = [name for name in ABLATED if getattr(self.transfer, name) != getattr(self._default("transfer"), name)]
        if ablated:
            raise InputError(f"transfer: {', '.join(ablated)} cannot be set there: choose an ablation (--ablations)")
        self.evaluate = self._shared_into("evaluate", ("resolution", "seed"))

    def _default(self, name: str):
        return next(f for f in fields(self) if f.name == name).default_factory()

    def _shared_into(self, name: str, shared: tuple[str, ...]):
        """The nested config ``name`` with the protocol's own values of ``shared``; a value set there that differs is
        refused
        (one left at the nested config's default cannot be told from one not set, and takes the protocol's). The copy
        remembers the values it was given (``_from_protocol``), so that ``dataclasses.replace`` of a shared field on a
        built config, which hands the same nested config to the new one, takes the new value instead of refusing it."""
        nested, default = getattr(self, name), self._default(name)
        given = getattr(nested, "_from_protocol", {})
        wrong = [
            key
            for key in shared
            if getattr(nested, key) not in (getattr(self, key), getattr(default, key))
            and getattr(nested, key) != given.get(key)
        ]
        if wrong:
            raise InputError(
                f"{name}: {', '.join(wrong)} cannot be set there: set the protocol's own {', '.join(wrong)}"
            )
        resolved = replace(nested, **{key: getattr(self, key) for key in shared})
        resolved._from_protocol = {key: getattr(self, key) for key in shared}
        return resolved

    def transfer_config(self, device: str = "auto") -> TransferConfig:
        """The settings of every transfer (the ablations change them further), on ``device``."""
        return replace(self.transfer, device=device)

    def evaluate_config(self) -> EvaluateConfig:
        """The settings of the unconditional protocol's set metrics."""
        return self.evaluate


def cache_settings(cfg: ProtocolConfig, generator_lit: bool) -> dict:
    """The settings a :class:`TransferCache` is made with: every setting of ``cfg`` that changes a transfer, not
    which transfers run or how they are judged (protocols, ablations, queries, baselines, lighting, unseen_views,
    lowpass_sigma: a cached transfer is re-judged), with every transfer's resolved settings (``transfer_config``,
    so that a changed TransferConfig default never reuses old transfers) and whether the GAN was trained lit."""
    transfer = asdict(cfg.transfer)
    own = {name: transfer[name] for name in FORMER_FIELDS}
    # Settings that do what the runs before these fields did are left out: their folders still match.
    if own["patch_scales"] == 0:
        del own["patch_scales"]
    if not own["pose_search"]:
        del own["pose_search"]
    judged = ("protocols", "ablations", "queries", "baselines", "lighting", "unseen_views", "lowpass_sigma")
    # The automaton's fit is not cached (a method beside the transfers, not a transfer).
    settings = {
        "resolution": cfg.resolution,
        **own,
        **{name: getattr(cfg.evaluate, name) for name in FORMER_EVALUATE_FIELDS},
        **{k: v for k, v in asdict(cfg).items() if k not in (*judged, "resolution", "transfer", "evaluate")},
    }
    defaults = asdict(TransferConfig())
    further = {
        k: v
        for k, v in transfer.items()
        if k not in (*FORMER_FIELDS, *SHARED, *ABLATED, *NOT_TRANSFER) and v != defaults[k]
    }
    if further:
        settings["transfer"] = further
    settings["transfer_config"] = {
        k: v for k, v in asdict(cfg.transfer_config()).items() if k not in ("device", *NOT_TRANSFER)
    }
    settings["generator_lit"] = generator_lit
    return settings


@dataclass(frozen=True)
class ProtocolInputs:
    """What every protocol of one run shares: the GAN (``generator_lit``: trained under the light prior, see
    ``TransferConfig.light``) and its camera (``distance``, ``fov``), the world and its prepared ``shapes``
    by name (``targets``: query shape -> the shape ``other_shape`` textures), the style VGG and the set
    metrics' feature extractor, the config, the pose and NOC checkpoints, the device, the output folder
    (None: nothing written), the log and the cache of finished transfers (None: none)."""

    generator: object
    generator_lit: bool
    distance: float
    fov: float
    world: World
    shapes: dict[str, PreparedShape]
    targets: dict[str, str]
    vgg: object
    extractor: object
    cfg: ProtocolConfig
    pose_checkpoint: str | Path | None
    noc_checkpoint: str | Path | None
    device: torch.device
    out: Path | None
    log: Callable[[str], None]
    cache: TransferCache | None
