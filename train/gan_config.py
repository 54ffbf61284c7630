"""The settings of ``mesh2tex train gan`` (:class:`TrainGanConfig`, with its optimiser's in :class:`OptimConfig`),
checked once; the trainer: :mod:`mesh2tex.train.gan`."""

from __future__ import annotations

from dataclasses import dataclass, field

from mesh2tex.config import check_fields
from mesh2tex.losses.augment import AugmentConfig
from mesh2tex.losses.gan import GanLossConfig
from mesh2tex.nn.discriminator import DiscriminatorConfig
from mesh2tex.nn.generator import GeneratorConfig
from mesh2tex.render import CameraConfig, LightConfig, RenderSettings


@dataclass
class OptimConfig:
    lr_encoder: float = 1e-4  # Adam learning rate of the geometry encoder (paper: 1e-4)
    lr_generator: float = 12e-4  # mapping network and synthesis (paper: 12e-4)
    lr_field: float = 1e-4  # neural field psi (paper: 1e-4)
    lr_discriminator: float = 14e-4  # both discriminators (paper: 14e-4)
    beta1: float = 0.0  # Adam beta1 (paper: 0)
    beta2: float = 0.99  # Adam beta2 (paper: 0.99)
    # Annealing: from iteration lr_decay_start (0: never) every rate falls linearly, over lr_decay_iters
    # iterations, to lr_decay_to times its value, and stays there. At constant rates a long run's
    # generator keeps swinging its whole palette from one few hundred iterations to the next, and its
    # EMA averages those palettes into duller colours (docs/results/gan.md, "The palette swings").
    lr_decay_start: int = 0
    lr_decay_iters: int = 2000
    lr_decay_to: float = 0.25

    def __post_init__(self):
        check_fields(
            self,
            positive=("lr_encoder", "lr_generator", "lr_field", "lr_discriminator", "lr_decay_iters"),
            at_least={"lr_decay_start": 0},
            between={"beta1": (0.0, 0.9999), "beta2": (0.0, 0.9999), "lr_decay_to": (0.0, 1.0)},
        )

    def lr_scale(self, iteration: int) -> float:
        """The annealing factor of every learning rate in the step from ``iteration`` to the next (1 up
        to ``lr_decay_start``)."""
        if not self.lr_decay_start or iteration <= self.lr_decay_start:
            return 1.0
        done = min(1.0, (iteration - self.lr_decay_start) / self.lr_decay_iters)
        return 1.0 - (1.0 - self.lr_decay_to) * done

    def learning_rates(self, iteration: int = 0) -> dict[str, list[float]]:
        """{optimizer: learning rate of each of its parameter groups at ``iteration``}, in the order the trainer builds
        them."""
        k = self.lr_scale(iteration)
        return {"g": [k * self.lr_encoder, k * self.lr_generator, k * self.lr_field], "d": [k * self.lr_discriminator]}


@dataclass
class TrainGanConfig:
    seed: int = 0  # seed of every random choice of the run
    iters: int = 20000  # training iterations
    batch: int = 2  # shapes per iteration and process (paper: 2)
    views: int = 4  # random views per shape (paper: 8)
    resolution: int = 128  # render and image resolution (a power of two)
    # fakes rendered at resolution x this and box-filtered down, as the photos are antialiased (1: one sample per
    # pixel)
    supersample: int = 1
    device: str = "auto"  # auto, cpu or cuda
    mixed_precision: bool = True  # bfloat16 autocast for the main phases on CUDA (ignored on a CPU)
    ema_halflife_images: float = 5000.0  # EMA of the generator: half-life in rendered images
    ema_rampup: float = 0.05  # the half-life is at most this fraction of the images seen so far (0: no ramp-up)
    log_every: int = 10  # iterations between metrics.jsonl records
    sample_every: int = 500  # iterations between sample grids under RUN/samples (0: only at the end)
    checkpoint_every: int = 500  # iterations between checkpoints (0: only at the end)
    snapshot_every: int = 0  # iterations between kept float16 EMA generators under RUN/snapshots (0: none)
    keep_snapshots: int = 0  # snapshots kept under RUN/snapshots, the newest (0: all)
    # iterations whose whole training state is kept as RUN/checkpoints/iterNNNNNNN.safetensors, for other runs to
    # start from (--resume FILE): a branch with other settings from there, without training the shared start again
    keep_checkpoints: list[int] = field(default_factory=list)
    # iterations between the held-out metric (SWD, diversity) that picks RUN/best.safetensors (0: none)
    metric_every: int = 0
    metric_photos: int = 16  # photos held out of training for the metric, the last by name (only when metric_every > 0)
    sample_shapes: int = 4  # shapes in a sample grid
    generator: GeneratorConfig = field(default_factory=GeneratorConfig)
    discriminator: DiscriminatorConfig = field(default_factory=DiscriminatorConfig)
    loss: GanLossConfig = field(default_factory=GanLossConfig)
    augment: AugmentConfig = field(default_factory=AugmentConfig)  # of every discriminator input, real and fake
    optim: OptimConfig = field(default_factory=OptimConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    lighting: LightConfig = field(
        default_factory=LightConfig
    )  # fakes are shaded like photos, so the generator learns albedo

    def __post_init__(self):
        check_fields(
            self,
            at_least={
                "log_every": 1,
                "sample_every": 0,
                "checkpoint_every": 0,
                "snapshot_every": 0,
                "keep_snapshots": 0,
                "metric_every": 0,
                "metric_photos": 1,
                "sample_shapes": 1,
                "ema_rampup": 0,
                "iters": 1,
                "batch": 1,
                "views": 1,
            },
            positive=("ema_halflife_images",),
        )
        if any(not isinstance(it, int) or it < 1 for it in self.keep_checkpoints):
            raise ValueError(f"keep_checkpoints must be iterations of at least 1, got {self.keep_checkpoints}")
        r = self.render_settings.resolution  # checks resolution and supersample
        if r < 8 or r & (r - 1):  # the discriminators halve it down to 4 x 4
            raise ValueError(f"resolution must be a power of two >= 8, got {r}")
        self.discriminator.check_resolution(r)

    @property
    def render_settings(self) -> RenderSettings:
        """How the fakes are rendered: ``resolution`` and ``supersample``, lit by the light prior when it is on."""
        return RenderSettings(self.resolution, self.supersample, "photo" if self.lighting.enabled else "albedo")


# ------------------------------------------------------------------------------------------ data
