"""Mesh neural cellular automata (MeshNCA): a tiny update rule that grows a texture on any mesh.

Cells live on the vertices of a mesh; each holds a state of ``channels`` numbers. One step:

    perception   z_i = (nominal_valence / deg_i) * sum_{j in N(i)} Y(d_ij) (s_j - s_i)
                 d_ij the unit direction from vertex i to vertex j (optionally rotated about the
                 normal of i by an orientation angle), Y the real spherical harmonics up to
                 ``sh_order`` in Schmidt semi-normalisation (order 0: 1; order 1: (y, z, x);
                 order 2: sqrt(3) xy, sqrt(3) yz, (3 z^2 - 1) / 2, sqrt(3) xz, sqrt(3)/2 (x^2 - y^2)).
                 On a regular grid with unit spacing order 0 is the discrete Laplacian and order 1
                 twice the gradient, the Laplacian and Sobel filters of a grid NCA. The mean over
                 neighbours, rescaled to a nominal valence, lets one rule run on meshes of any valence.
    update       ds_i = MLP([z_i, s_i]): Linear(K C + C, hidden) -> ReLU -> Linear(hidden, C), the
                 last layer starting at zero; applied to each cell with probability ``update_rate``
                 (asynchronous updates): s_i <- s_i + ds_i.

K = (sh_order + 1)^2 harmonics. At the paper's sizes (16 channels, order 1, hidden 128) the update
rule has 12,432 parameters. Perception has none: it is fixed by the mesh (:class:`CellGraph`).

Readouts turn states into colours (RGB in [-1, 1]) at surface points (triangle, barycentrics):
    linear  a linear map of the state, interpolated with the barycentrics (equivalently: of the
            interpolated state); colour detail is limited to the vertex spacing.
    lppn    a local pattern-producing network: a small SIREN on the interpolated state and the
            sorted, CDF-remapped barycentric coordinates (:func:`mesh2tex.nn.field.sorted_cdf_coordinates`,
            the same on both sides of an edge), so colour is defined at any resolution.

Shapes: states (B, V, C); graphs hold (V, 3) positions and normals and an (E,) directed edge list.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn

from mesh2tex.checks import check_shape, check_type
from mesh2tex.config import MAX_CHANNELS, check_fields
from mesh2tex.nn.cell_graph import NEIGHBOURHOODS, CellGraph, build_cell_graph, num_harmonics, perceive
from mesh2tex.nn.faceconv import take_rows
from mesh2tex.nn.field import sorted_cdf_coordinates, vertex_features

READOUTS = ("linear", "lppn")
SEED_MODES = ("zero", "noise")


@dataclass
class NCAConfig:
    channels: int = 16  # state size per cell
    hidden: int = 128  # width of the update MLP
    sh_order: int = 1  # spherical harmonics up to this order (0, 1 or 2)
    update_rate: float = 0.5  # probability that a cell updates at a step
    nominal_valence: float = 4.0  # mean aggregation times this (a quad mesh's edge valence)
    neighbourhood: str = "edges"  # "edges", or "edges+diagonals" (quads: valence 8)
    seed: str = "zero"  # initial state: "zero" or "noise" (uniform in [-0.5, 0.5])
    readout: str = "linear"  # "linear" or "lppn"
    lppn_hidden: int = 32  # width of the LPPN
    lppn_frequency: float = 3.0  # SIREN frequency of the local coordinates (periods per triangle ~ this / pi)

    def __post_init__(self):
        check_fields(
            self,
            at_least={"channels": 3},
            between={"hidden": (1, MAX_CHANNELS), "lppn_hidden": (1, MAX_CHANNELS)},
            positive=("lppn_frequency",),
        )
        if self.channels > MAX_CHANNELS:
            raise ValueError(f"nca.channels must be at most {MAX_CHANNELS}, got {self.channels}")
        if self.sh_order not in (0, 1, 2):
            raise ValueError(f"nca.sh_order must be 0, 1 or 2, got {self.sh_order}")
        if not 0.0 < self.update_rate <= 1.0:
            raise ValueError(f"nca.update_rate must be in (0, 1], got {self.update_rate}")
        if self.nominal_valence <= 0:
            raise ValueError(f"nca.nominal_valence must be positive, got {self.nominal_valence}")
        for name, value, options in (
            ("neighbourhood", self.neighbourhood, NEIGHBOURHOODS),
            ("readout", self.readout, READOUTS),
            ("seed", self.seed, SEED_MODES),
        ):
            if value not in options:
                raise ValueError(f"nca.{name} must be one of {options}, got {value!r}")


class LinearReadout(nn.Module):
    """State -> RGB by one linear map; at surface points it acts on the interpolated state."""

    def __init__(self, channels: int):
        super().__init__()
        self.linear = nn.Linear(channels, 3)

    def forward(self, corner_states: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
        """corner_states (P, 3, C), bary (P, 3) -> (P, 3)."""
        return self.linear((corner_states * bary[..., None]).sum(1))


class LPPNReadout(nn.Module):
    """A small SIREN: [interpolated state, sorted-CDF barycentrics] -> RGB (see the module docstring).

    The first layer is sin(frequency * W_p p + W_s s + b); the hidden layer sin(W h + b); the output
    linear. Initialisation as in SIREN: the coordinate weights U(-1/3, 1/3), the hidden weights
    U(-sqrt(6/n), sqrt(6/n)).
    """

    def __init__(self, channels: int, hidden: int, frequency: float):
        super().__init__()
        self.frequency = float(frequency)
        self.coords = nn.Linear(3, hidden, bias=False)
        self.state = nn.Linear(channels, hidden)
        self.hidden = nn.Linear(hidden, hidden)
        self.out = nn.Linear(hidden, 3)
        with torch.no_grad():
            self.coords.weight.uniform_(-1.0 / 3.0, 1.0 / 3.0)
            bound = math.sqrt(6.0 / hidden)
            self.hidden.weight.uniform_(-bound, bound)

    def forward(self, corner_states: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
        """corner_states (P, 3, C), bary (P, 3) -> (P, 3)."""
        s = (corner_states * bary[..., None]).sum(1)
        p = sorted_cdf_coordinates(bary.float()).to(s.dtype)
        h = torch.sin(self.frequency * self.coords(p) + self.state(s))
        h = torch.sin(self.hidden(h))
        return self.out(h)


class MeshNCA(nn.Module):
    """The update rule and its readout (see the module docstring)."""

    def __init__(self, cfg: NCAConfig | None = None):
        super().__init__()
        self.cfg = cfg = cfg or NCAConfig()
        k = num_harmonics(cfg.sh_order)
        self.update = nn.Sequential(
            nn.Linear(k * cfg.channels + cfg.channels, cfg.hidden), nn.ReLU(), nn.Linear(cfg.hidden, cfg.channels)
        )
        with torch.no_grad():  # start as the identity map, as grid NCAs do
            self.update[2].weight.zero_()
            self.update[2].bias.zero_()
        self.readout = (
            LinearReadout(cfg.channels)
            if cfg.readout == "linear"
            else LPPNReadout(cfg.channels, cfg.lppn_hidden, cfg.lppn_frequency)
        )

    def rule_parameters(self) -> int:
        """Parameters of the update rule alone (12,432 at the paper's sizes)."""
        return sum(p.numel() for p in self.update.parameters())

    def seed_state(
        self, batch: int, num_cells: int, device=None, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """(batch, num_cells, channels) initial states: zeros, or uniform noise in [-0.5, 0.5]."""
        shape = (batch, num_cells, self.cfg.channels)
        if self.cfg.seed == "zero":
            return torch.zeros(shape, device=device)
        return torch.rand(shape, generator=generator).to(device) - 0.5

    def _check_state(self, method: str, state: torch.Tensor, graph: CellGraph | None = None) -> None:
        """state (B, V, C) float with C = cfg.channels (and V = graph.num_cells when a graph is given)."""
        cells = None
        if graph is not None:
            cells = check_type(graph, f"MeshNCA.{method}: graph", CellGraph).num_cells
        check_shape(state, f"MeshNCA.{method}: state", (None, cells, self.cfg.channels), dtype="float")

    def delta(self, state: torch.Tensor, graph: CellGraph, angle: float | torch.Tensor = 0.0) -> torch.Tensor:
        """The deterministic update ds (B, V, C) of every cell: state (B, V, C) float, V = ``graph.num_cells``;
        ``angle`` a float or (V,) radians (see :meth:`CellGraph.directions`)."""
        self._check_state("delta", state, graph)
        if torch.is_tensor(angle):
            check_shape(angle, "MeshNCA.delta: angle", (), (graph.num_cells,))
        z = perceive(state, graph, self.cfg.sh_order, self.cfg.nominal_valence, angle)
        return self.update(torch.cat([z, state], dim=-1))

    def step(
        self,
        state: torch.Tensor,
        graph: CellGraph,
        angle: float | torch.Tensor = 0.0,
        graft: tuple["MeshNCA", torch.Tensor] | None = None,
        generator: torch.Generator | None = None,
    ) -> torch.Tensor:
        """One asynchronous step: state (B, V, C) float -> (B, V, C), V = ``graph.num_cells``.

        ``graft``: (other automaton of the same lineage, alpha (V,) in [0, 1]): the update becomes
        alpha * other's + (1 - alpha) * this one's, cell by cell (MeshNCA's grafting).
        """
        self._check_state("step", state, graph)
        ds = self.delta(state, graph, angle)
        if graft is not None:
            other, alpha = graft
            check_shape(alpha, "MeshNCA.step: graft alpha", (graph.num_cells,))
            a = alpha.to(ds.dtype).reshape(1, -1, 1)
            ds = (1 - a) * ds + a * other.delta(state, graph, angle)
        fire = torch.rand(state.shape[:2], generator=generator, device=state.device)  # a generator on state's device
        fire = (fire < self.cfg.update_rate).to(state.dtype)[..., None]
        return state + ds * fire

    def rollout(self, state: torch.Tensor, graph: CellGraph, steps: int, **kwargs) -> torch.Tensor:
        """``steps`` calls of :meth:`step`; keyword arguments are passed on."""
        for _ in range(int(steps)):
            state = self.step(state, graph, **kwargs)
        return state

    def colours(
        self,
        state: torch.Tensor,
        triangles: torch.Tensor,
        triangle_id: torch.Tensor,
        bary: torch.Tensor,
        sample: torch.Tensor | None = None,
        graft: tuple["MeshNCA", torch.Tensor] | None = None,
    ) -> torch.Tensor:
        """RGB (P, 3) in about [-1, 1] at P surface points.

        state (B, V, C) float; triangles (T, 3) int64; triangle_id (P,) int64 and bary (P, 3) float
        locate the points; sample (P,) int64 the state each point reads (None: all read state 0).
        ``graft``: (other automaton, alpha (V,)) as in :meth:`step`: where cells grew by the other's
        rule they are read by its readout too, the two blended by alpha interpolated at the point.
        """
        self._check_state("colours", state)
        check_shape(triangles, "MeshNCA.colours: triangles", (None, 3), dtype="int")
        points = check_shape(triangle_id, "MeshNCA.colours: triangle_id", ("P",), dtype="int")
        check_shape(bary, "MeshNCA.colours: bary", ("P", 3), sizes=points, dtype="float")
        if sample is not None:
            check_shape(sample, "MeshNCA.colours: sample", ("P",), sizes=points, dtype="int")
        corners = triangles[triangle_id]  # (P, 3)
        if sample is None:
            corner_states = take_rows(state[0], corners)  # (P, 3, C)
        else:  # cell (sample, vertex) is row sample * V + vertex of the (B V, C) states
            corner_states = take_rows(state.reshape(-1, state.shape[2]), sample[:, None] * state.shape[1] + corners)
        bary = bary.to(state.dtype)
        rgb = self.readout(corner_states, bary)
        if graft is None:
            return rgb
        other, alpha = graft
        check_shape(alpha, "MeshNCA.colours: graft alpha", (state.shape[1],))
        a = (alpha.to(state.dtype)[corners] * bary).sum(-1, keepdim=True)  # (P, 1)
        return (1 - a) * rgb + a * other.readout(corner_states, bary)

    def vertex_colours(self, state: torch.Tensor, graft: tuple["MeshNCA", torch.Tensor] | None = None) -> torch.Tensor:
        """(B, V, 3) colours at the cells themselves (a point at a vertex: barycentrics (1, 0, 0)) of state (B, V, C);
        ``graft`` as in :meth:`colours`."""
        self._check_state("vertex_colours", state)
        b, v, c = state.shape
        corners = state.reshape(b * v, 1, c).expand(b * v, 3, c)
        bary = torch.tensor([1.0, 0.0, 0.0], dtype=state.dtype, device=state.device).expand(b * v, 3)
        rgb = self.readout(corners, bary).reshape(b, v, 3)
        if graft is None:
            return rgb
        other, alpha = graft
        check_shape(alpha, "MeshNCA.vertex_colours: graft alpha", (v,))
        a = alpha.to(state.dtype).reshape(1, v, 1)
        return (1 - a) * rgb + a * other.readout(corners, bary).reshape(b, v, 3)


def overflow_penalty(state: torch.Tensor, rgb: torch.Tensor | None = None) -> torch.Tensor:
    """sum over channels of |s - clamp(s, -1, 1)|, mean over cells (and the same for colours outside [-1, 1])."""
    loss = (state - state.clamp(-1.0, 1.0)).abs().sum(-1).mean()
    if rgb is not None:
        loss = loss + (rgb - rgb.clamp(-1.0, 1.0)).abs().sum(-1).mean()
    return loss


@dataclass
class AutomatonTexture:
    """An automaton's colours on its cell mesh (a :class:`mesh2tex.render.surface_texture.SurfaceTexture`):
    ``model`` read out at ``state`` (1, V, C) over ``triangles`` (T, 3) of the cells; ``graft``:
    (other automaton, alpha (V,)) as in :meth:`MeshNCA.colours`."""

    model: "MeshNCA"
    state: torch.Tensor
    triangles: torch.Tensor
    graft: tuple | None = None

    def colours(self, triangle_id: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
        device = self.state.device
        return self.model.colours(
            self.state, self.triangles.to(device), triangle_id.to(device), bary.to(device), graft=self.graft
        )


class ConditionedNCA(nn.Module):
    """The automaton as the texture GAN's feature generator (``generator.kind: nca``).

    Cells are the finest vertices of a :class:`~mesh2tex.nn.batch.MeshBatch` (all shapes at once;
    shapes share no edge, so they do not talk). Each cell carries a condition
    c_i = [A w_s, G e_i]: the latent w of its shape through a linear map A, and the mean geometry
    feature e_i of the encoder's finest output E_0 over its quads through G. The update reads
    [z_i, s_i, c_i]; states start from a linear seed of the condition, s_i = S c_i (so that
    different latents differ from the first iteration), and grow for ``steps`` asynchronous steps,
    with gradients through every step. Output: the vertex states (V, C).

    Args:
        channels: C, the state size per cell. hidden: width of the update MLP. steps: steps grown.
        condition: width of each of the two conditions (the latent's, the geometry's).
        w_dim: the latent w's size. geometry_dim: the channels of the encoder's E_0.
        sh_order: order of the spherical harmonics the perception projects neighbours' differences on.
        update_rate: the chance a cell fires at a step. nominal_valence: the neighbour count the
            perception's sums are scaled to. neighbourhood: "edges" or "faces" (which vertices are neighbours).
        output_init: scale of the update's last layer at initialisation (small: states start near the seed).
    """

    def __init__(
        self,
        channels: int,
        hidden: int,
        steps: int,
        condition: int,
        w_dim: int,
        geometry_dim: int,
        sh_order: int = 1,
        update_rate: float = 0.5,
        nominal_valence: float = 4.0,
        neighbourhood: str = "edges",
        output_init: float = 0.1,
    ):
        super().__init__()
        if steps < 1 or channels < 1 or condition < 1:
            raise ValueError("the NCA generator needs steps, channels and condition of at least 1")
        self.channels, self.steps, self.sh_order = channels, steps, sh_order
        self.update_rate, self.nominal_valence, self.neighbourhood = update_rate, nominal_valence, neighbourhood
        self.from_w = nn.Linear(w_dim, condition)
        self.from_geometry = nn.Linear(geometry_dim, condition)
        k = num_harmonics(sh_order)
        self.seed = nn.Linear(2 * condition, channels)
        self.update = nn.Sequential(
            nn.Linear(k * channels + channels + 2 * condition, hidden), nn.ReLU(), nn.Linear(hidden, channels)
        )
        with torch.no_grad():
            self.update[2].weight.mul_(output_init)
            self.update[2].bias.zero_()

    def forward(self, batch, w: torch.Tensor, geometry: torch.Tensor, noise_mode: str = "random") -> torch.Tensor:
        """batch: MeshBatch; w (B, w_dim) one per shape; geometry (F_0, G) -> vertex states (V, C).

        ``noise_mode`` "none" fixes which cells fire at each step (a seeded draw), so that inference
        is deterministic; "random" draws them afresh.
        """
        check_shape(w, "ConditionedNCA: w", (batch.num_shapes, self.from_w.in_features), dtype="float")
        check_shape(
            geometry, "ConditionedNCA: geometry", (batch.quads.shape[0], self.from_geometry.in_features), dtype="float"
        )
        device = w.device
        graph = build_cell_graph(
            batch.vertices.detach().cpu().numpy(), batch.quads.cpu().numpy(), self.neighbourhood
        ).to(device)
        shape_of_vertex = batch.vertex_shape.to(device)
        vertex_geometry = vertex_features(geometry.to(w.dtype), batch.quads, batch.num_vertices)
        condition = torch.cat([self.from_w(w)[shape_of_vertex], self.from_geometry(vertex_geometry)], dim=1)[
            None
        ]  # (1, V, 2c)
        generator = torch.Generator(device=device).manual_seed(0) if noise_mode == "none" else None
        state = self.seed(condition)
        for _ in range(self.steps):
            z = perceive(state, graph, self.sh_order, self.nominal_valence)
            ds = self.update(torch.cat([z, state, condition], dim=-1))
            fire = (torch.rand(state.shape[:2], generator=generator, device=device) < self.update_rate).to(state.dtype)[
                ..., None
            ]
            state = state + ds * fire
        return state[0]
