"""The mesh-field texture generator: geometry encoder, mapping network, face-convolution synthesis U-Net
and the neural field psi.

    face features ─► encoder (FaceResNet per level, max-pool to the next) ─► E_0 ... E_{L-1}
    z (512) ─► mapping ─► w ─► ws (B, num_ws, 512)
    synthesis, coarsest level first: block_l(unpool(x_{l+1}) ‖ E_l, ws) ─► x_l, rgb_l = unpool(rgb_{l+1}) + toRGB(x_l)
    F_c = x_0 (per finest face), face colours = rgb_0 (the proxy texture)
    psi(barycentrics, blend of vertex means of F_c [‖ P E_0]) + blend of vertex means of rgb_0 ─► colour at any point

psi sees the latent-dependent F_c and, with ``field_geometry_channels`` > 0, a learnt narrow linear
projection P E_0 of the geometry features. Fed E_0 whole (as the paper's figure draws it) psi learns
to read the latent-free, face-to-face noisy geometry channels and ignore F_c: every latent then
gets the same texture. With ``field_residual`` psi's output is a residual on the barycentric blend of
the proxy colours rgb_0 (mean face colour around each vertex): the texture starts from the
latent-dependent per-face colours, which the proxy discriminator trains directly, and psi adds the
detail within faces (see :meth:`FaceTexture.colours`).

The feature generator (the synthesis) is one of the kinds of :mod:`mesh2tex.nn.synthesis`, chosen by
``kind``: the U-Net of face convolutions above (``faceconv``), or a mesh cellular automaton on the
finest vertices (``nca``: each cell conditioned on w and on E_0, F_c the mean state of each face's
corners, a linear readout of it the face colour; num_ws = 1); psi and everything downstream are the
same for every kind.

Each synthesis block uses three ws (conv0, conv1, toRGB), so num_ws = 3 * num_levels. Texture
transfer optimises ws and then the parameters of the last (finest) synthesis blocks:
:meth:`TextureGenerator.last_synthesis_parameters`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch
from torch import nn

from mesh2tex.checks import check_shape, check_type
from mesh2tex.config import MAX_CHANNELS, check_fields
from mesh2tex.nn.batch import MeshBatch
from mesh2tex.nn.faceconv import FaceConv, FaceResNetBlock, FullyConnected, face_pool
from mesh2tex.nn.field import NeuralField, blend_vertex_features, vertex_features
from mesh2tex.nn.synthesis import SYNTHESIS_KINDS, AutomatonSynthesis


@dataclass
class GeneratorConfig:
    z_dim: int = 512  # latent texture code size
    w_dim: int = 512  # intermediate latent size
    mapping_layers: int = 8  # fully connected layers of the mapping network
    mapping_lr_multiplier: float = 0.01  # StyleGAN2's reduced learning rate of the mapping network
    input_features: int = 0  # face-feature columns of the prepared shapes (0: taken from the data)
    encoder_channels: list[int] = field(default_factory=lambda: [32, 64, 64, 96, 96])  # per level, finest first
    synthesis_channels: list[int] = field(default_factory=lambda: [32, 64, 64, 96, 96])  # per level, finest first
    pool_mode: str = "max"  # encoder pooling: max or mean
    field_hidden: int = 128  # width of the neural field MLP
    aux_latent_dim: int = 512  # size of the learnt auxiliary latent of psi
    field_coords: str = "raw"  # local coordinates of psi: raw (barycentrics) or sorted_cdf
    field_geometry_channels: int = 0  # E_0 channels psi sees besides F_c, through a learnt projection (0: F_c alone)
    field_residual: bool = True  # psi adds to the blended proxy (per-face) colours instead of painting from scratch
    rgb_output_init: float = 0.1  # initial weight scale of the toRGB layers (1: StyleGAN2's, fresh colours near +-2)
    field_output_init: float = 0.1  # initial weight scale of psi's output layer (1 starts from saturated colours)
    conv_clamp: float = 256.0  # clamp of synthesis activations (keeps mixed precision finite)
    # the feature generator (mesh2tex.nn.synthesis): "faceconv" (the synthesis U-Net) or "nca" (a mesh cellular
    # automaton)
    kind: str = "faceconv"
    nca_channels: int = 16  # kind nca: state size per cell (the F_c channels psi blends)
    nca_hidden: int = 64  # kind nca: width of the update MLP
    nca_steps: int = 12  # kind nca: steps grown from the seed (a linear map of each cell's condition)
    nca_condition: int = 16  # kind nca: width of each of the latent and the geometry conditions per cell

    def __post_init__(self):
        check_fields(
            self,
            at_least={"mapping_layers": 1, "input_features": 0, "field_geometry_channels": 0, "nca_steps": 1},
            positive=("mapping_lr_multiplier", "conv_clamp"),
            between={
                name: (1, MAX_CHANNELS)
                for name in (
                    "z_dim",
                    "w_dim",
                    "encoder_channels",
                    "synthesis_channels",
                    "field_hidden",
                    "aux_latent_dim",
                    "nca_channels",
                    "nca_hidden",
                    "nca_condition",
                )
            },
        )
        if self.kind not in SYNTHESIS_KINDS:
            raise ValueError(f"kind must be one of {tuple(SYNTHESIS_KINDS)}, got {self.kind!r}")
        if not self.synthesis_channels or len(self.encoder_channels) != len(self.synthesis_channels):
            raise ValueError(
                f"encoder_channels and synthesis_channels need one entry per level each "
                f"(got {len(self.encoder_channels)} and {len(self.synthesis_channels)})"
            )

    @property
    def num_levels(self) -> int:
        return len(self.synthesis_channels)


class MappingNetwork(nn.Module):
    """z (B, z_dim) -> ws (B, num_ws, w_dim), tracking the mean w for the truncation trick."""

    def __init__(
        self,
        z_dim: int,
        w_dim: int,
        num_ws: int,
        layers: int = 8,
        lr_multiplier: float = 0.01,
        w_avg_beta: float = 0.995,
    ):
        super().__init__()
        self.num_ws, self.w_avg_beta = num_ws, w_avg_beta
        dims = [z_dim] + [w_dim] * layers
        self.net = nn.Sequential(
            *[
                FullyConnected(a, b, activation="lrelu", lr_multiplier=lr_multiplier)
                for a, b in zip(dims[:-1], dims[1:])
            ]
        )
        self.register_buffer("w_avg", torch.zeros(w_dim))

    def forward(self, z: torch.Tensor, truncation_psi: float = 1.0, update_w_avg: bool = False) -> torch.Tensor:
        """z (B, z_dim) float -> ws (B, num_ws, w_dim)."""
        check_shape(z, "MappingNetwork: z", (None, self.net[0].weight.shape[1]), dtype="float")
        z = z * (z.square().mean(dim=1, keepdim=True) + 1e-8).rsqrt()  # normalise the second moment
        w = self.net(z)
        if update_w_avg:
            self.w_avg.copy_(w.detach().mean(0).lerp(self.w_avg, self.w_avg_beta))
        if truncation_psi != 1.0:
            w = self.w_avg.lerp(w, truncation_psi)
        return w.unsqueeze(1).repeat(1, self.num_ws, 1)


class GeometryEncoder(nn.Module):
    """Face features (F_0, C_in) -> per-level geometry features [E_0 (F_0, c_0), ..., E_{L-1}]."""

    def __init__(self, in_features: int, channels: list[int], pool_mode: str = "max"):
        super().__init__()
        self.pool_mode = pool_mode
        self.stem = FaceConv(in_features, channels[0])
        self.blocks = nn.ModuleList(FaceResNetBlock(channels[max(l - 1, 0)], channels[l]) for l in range(len(channels)))

    def forward(self, batch: MeshBatch) -> list[torch.Tensor]:
        x = self.stem(batch.face_features, batch.neighbors[0])
        features = []
        for level, block in enumerate(self.blocks):
            if level > 0:
                x = face_pool(x, batch.pool[level - 1], batch.num_faces(level), self.pool_mode)
            x = block(x, batch.neighbors[level])
            features.append(x)
        return features


@dataclass
class FaceTexture:
    """The generator's texture on a batch of shapes: per finest face, and bound to the generator and
    the batch it was made for, the colour at any point of their triangles (a
    :class:`mesh2tex.render.surface_texture.SurfaceTexture`).

    field_features (F_0, C_field) float  the features psi blends (F_c, or [F_c ‖ P E_0])
    face_rgb       (F_0, 3) float        the per-face colours (proxy texture), nominally in [-1, 1]
    generator, batch                     what :meth:`colours` evaluates psi with (None until bound:
                                         :meth:`bound`; ``TextureGenerator.synthesize`` returns it bound)
    """

    field_features: torch.Tensor
    face_rgb: torch.Tensor
    generator: "TextureGenerator | None" = field(default=None, repr=False, compare=False)
    batch: MeshBatch | None = field(default=None, repr=False, compare=False)

    def bound(self, generator: "TextureGenerator", batch: MeshBatch) -> "FaceTexture":
        """The same features bound to ``generator`` and ``batch`` (a texture read back from a file is not)."""
        return FaceTexture(self.field_features, self.face_rgb, generator, batch)

    def colours(self, triangle_id: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
        """psi at surface points: triangle_id (P,) int64 indices of ``batch.triangles()``, bary (P, 3) float
        -> RGB (P, 3) in [-1, 1] nominally.

        With ``field_residual`` (the default) psi's output is added to the barycentric blend of the
        proxy's vertex colours (the mean face colour around each vertex), so the colour at a point
        starts from the latent-dependent per-face texture and psi adds detail within the faces.
        """
        sizes = check_shape(triangle_id, "FaceTexture.colours: triangle_id", ("P",), dtype="int")
        check_shape(bary, "FaceTexture.colours: bary", ("P", 3), sizes=sizes, dtype="float")
        if self.generator is None or self.batch is None:
            raise ValueError(
                "FaceTexture.colours: the texture is not bound to a generator and a batch (FaceTexture.bound)"
            )
        features, residual = self.field_features, self.generator.cfg.field_residual
        if residual:
            features = torch.cat([features, self.face_rgb.to(features.dtype)], dim=1)
        vertex = vertex_features(features, self.batch.quads, self.batch.num_vertices)
        blended = blend_vertex_features(vertex, self.batch.triangles(), triangle_id, bary)
        if not residual:
            return self.generator.field(blended, bary)
        return self.generator.field(blended[:, :-3], bary) + blended[:, -3:]


class TextureGenerator(nn.Module):
    """The whole generator; submodules ``encoder``, ``mapping``, ``synthesis``, ``field`` take their own
    learning rates (see :meth:`parameter_groups`)."""

    def __init__(self, cfg: GeneratorConfig):
        super().__init__()
        if cfg.input_features <= 0:  # the one check the config cannot make: it is filled in from the data
            raise ValueError("GeneratorConfig.input_features must be set to the face-feature count of the shapes")
        self.cfg = cfg
        kind = SYNTHESIS_KINDS[cfg.kind]
        self.num_ws, encoder_levels = kind.sizes(cfg)
        self.encoder = GeometryEncoder(cfg.input_features, cfg.encoder_channels[:encoder_levels], cfg.pool_mode)
        self.mapping = MappingNetwork(cfg.z_dim, cfg.w_dim, self.num_ws, cfg.mapping_layers, cfg.mapping_lr_multiplier)
        self.synthesis = kind(cfg)
        self.field_geometry = (
            FullyConnected(cfg.encoder_channels[0], cfg.field_geometry_channels)
            if cfg.field_geometry_channels > 0
            else None
        )
        self.field_dim = self.synthesis.channels + cfg.field_geometry_channels
        self.field = NeuralField(
            self.field_dim, cfg.field_hidden, cfg.aux_latent_dim, cfg.field_coords, cfg.field_output_init
        )
        self.register_load_state_dict_pre_hook(_rename_former_keys)

    def synthesize(
        self, batch: MeshBatch, ws: torch.Tensor, encoded: list[torch.Tensor] | None = None, noise_mode: str = "random"
    ) -> FaceTexture:
        """Per-face texture for ``batch`` from ``ws`` (B, num_ws, w_dim) or (B, w_dim) float, one row per shape
        (B = ``batch.num_shapes``).

        ``encoded``: the encoder's output for this batch, if already computed (it does not depend on ws).
        """
        check_type(batch, "TextureGenerator.synthesize: batch", MeshBatch)
        shapes = {"B": (batch.num_shapes, "batch")}
        check_shape(
            ws,
            "TextureGenerator.synthesize: ws",
            ("B", self.num_ws, self.cfg.w_dim),
            ("B", self.cfg.w_dim),
            sizes=shapes,
            dtype="float",
        )
        if ws.dim() == 2:
            ws = ws.unsqueeze(1).expand(-1, self.num_ws, -1)
        if encoded is None:
            check_shape(
                batch.face_features, "TextureGenerator.synthesize: batch.face_features", (None, self.cfg.input_features)
            )
            encoded = self.encoder(batch)
        x, rgb = self.synthesis(batch, ws, encoded, noise_mode)
        features = x
        if self.field_geometry is not None:
            features = torch.cat([x, self.field_geometry(encoded[0].to(x.dtype))], dim=1)
        return FaceTexture(field_features=features, face_rgb=rgb, generator=self, batch=batch)

    def forward(
        self,
        batch: MeshBatch,
        z: torch.Tensor,
        truncation_psi: float = 1.0,
        noise_mode: str = "random",
        update_w_avg: bool = False,
    ):
        """z: (B, z_dim), one per shape -> (FaceTexture, ws (B, num_ws, w_dim))."""
        check_type(batch, "TextureGenerator: batch", MeshBatch)
        check_shape(
            z, "TextureGenerator: z", ("B", self.cfg.z_dim), sizes={"B": (batch.num_shapes, "batch")}, dtype="float"
        )
        ws = self.mapping(z, truncation_psi, update_w_avg)
        return self.synthesize(batch, ws, noise_mode=noise_mode), ws

    def last_synthesis_parameters(self, num_blocks: int = 2) -> list[nn.Parameter]:
        """The parameters texture transfer fine-tunes after the latent: the last ``num_blocks`` synthesis
        blocks (the finest levels), or what the kind names instead (the automaton: its update rule and
        colour readout)."""
        return self.synthesis.transfer_parameters(num_blocks)

    def parameter_groups(self) -> dict[str, list[nn.Parameter]]:
        """{"encoder", "generator" (mapping + synthesis), "field"}: the groups that get the paper's learning rates."""
        return {
            "encoder": list(self.encoder.parameters()),
            "generator": list(self.mapping.parameters()) + list(self.synthesis.parameters()),
            "field": list(self.field.parameters())
            + (list(self.field_geometry.parameters()) if self.field_geometry is not None else []),
        }


def _rename_former_keys(module, state_dict, prefix, *args) -> None:
    """Checkpoints of the automaton kind written before the kinds had one interface: their keys take
    today's names (:data:`AutomatonSynthesis.FORMER_PREFIXES`)."""
    for old, new in AutomatonSynthesis.FORMER_PREFIXES.items():
        for key in [k for k in state_dict if k.startswith(prefix + old)]:
            state_dict[prefix + new + key[len(prefix + old) :]] = state_dict.pop(key)
