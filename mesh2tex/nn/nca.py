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
import warnings
from dataclasses import dataclass, field

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from mesh2tex.checks import check_shape, check_type
from mesh2tex.config import MAX_CHANNELS, check_fields
from mesh2tex.geometry.prepared import quads_to_triangles
from mesh2tex.nn.faceconv import take_rows
from mesh2tex.nn.field import sorted_cdf_coordinates, vertex_features
from mesh2tex.render.shading import vertex_normals

NEIGHBOURHOODS = ("edges", "edges+diagonals")
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
        check_fields(self, at_least={"channels": 3}, between={"hidden": (1, MAX_CHANNELS), "lppn_hidden": (1, MAX_CHANNELS)},
                     positive=("lppn_frequency",))
        if self.channels > MAX_CHANNELS:
            raise ValueError(f"nca.channels must be at most {MAX_CHANNELS}, got {self.channels}")
        if self.sh_order not in (0, 1, 2):
            raise ValueError(f"nca.sh_order must be 0, 1 or 2, got {self.sh_order}")
        if not 0.0 < self.update_rate <= 1.0:
            raise ValueError(f"nca.update_rate must be in (0, 1], got {self.update_rate}")
        if self.nominal_valence <= 0:
            raise ValueError(f"nca.nominal_valence must be positive, got {self.nominal_valence}")
        for name, value, options in (("neighbourhood", self.neighbourhood, NEIGHBOURHOODS), ("readout", self.readout, READOUTS),
                                     ("seed", self.seed, SEED_MODES)):
            if value not in options:
                raise ValueError(f"nca.{name} must be one of {options}, got {value!r}")


def num_harmonics(order: int) -> int:
    return (order + 1) ** 2


def spherical_harmonics(directions: torch.Tensor, order: int) -> torch.Tensor:
    """(E, 3) unit vectors -> (E, (order+1)^2) real spherical harmonics, Schmidt semi-normalised."""
    x, y, z = directions.unbind(-1)
    basis = [torch.ones_like(x)]
    if order >= 1:
        basis += [y, z, x]
    if order >= 2:
        r3 = math.sqrt(3.0)
        basis += [r3 * x * y, r3 * y * z, 0.5 * (3 * z * z - 1), r3 * x * z, 0.5 * r3 * (x * x - y * y)]
    return torch.stack(basis, dim=-1)


@dataclass
class CellGraph:
    """The cells of one mesh: where they are and whom they hear.

    positions (V, 3) float32, normals (V, 3) unit, triangles (T, 3) int64 (for rendering and baking),
    receiver / sender (E,) int64 (cell ``receiver[e]`` hears ``sender[e]``; both directions listed),
    degree (V,) float32 (neighbours per cell, >= 1).
    """

    positions: torch.Tensor
    normals: torch.Tensor
    triangles: torch.Tensor
    receiver: torch.Tensor
    sender: torch.Tensor
    degree: torch.Tensor
    operators: dict = field(default_factory=dict, repr=False)  # perception operators, built on first use

    @property
    def num_cells(self) -> int:
        return int(self.positions.shape[0])

    def to(self, device) -> "CellGraph":
        return CellGraph(*(t.to(device) for t in (self.positions, self.normals, self.triangles, self.receiver, self.sender, self.degree)))  # operators rebuilt there

    def directions(self, angle: float | torch.Tensor = 0.0) -> torch.Tensor:
        """(E, 3) unit edge directions receiver -> sender, rotated by ``angle`` radians about the
        receiver's normal (a float, or (V,) per cell): the orientation control."""
        d = F.normalize(self.positions[self.sender] - self.positions[self.receiver], dim=-1)
        if not torch.is_tensor(angle) and angle == 0.0:
            return d
        angle = torch.as_tensor(angle, dtype=d.dtype, device=d.device)
        if angle.dim() == 1:
            angle = angle[self.receiver]
        n = self.normals[self.receiver]
        cos, sin = torch.cos(angle)[..., None], torch.sin(angle)[..., None]
        # Rodrigues' rotation about n.
        return d * cos + torch.linalg.cross(n, d) * sin + n * (n * d).sum(-1, keepdim=True) * (1 - cos)


def _unique_edges(faces: np.ndarray, neighbourhood: str) -> np.ndarray:
    """(M, 2) undirected vertex pairs of a face list (F, 3 or 4): the boundary edges of every face,
    plus for quads with "edges+diagonals" the two diagonals."""
    k = faces.shape[1]
    pairs = [np.stack([faces[:, i], faces[:, (i + 1) % k]], axis=1) for i in range(k)]
    if neighbourhood == "edges+diagonals" and k == 4:
        pairs += [faces[:, [0, 2]], faces[:, [1, 3]]]
    pairs = np.sort(np.concatenate(pairs), axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    return np.unique(pairs, axis=0)


def build_cell_graph(vertices, faces, neighbourhood: str = "edges") -> CellGraph:
    """A :class:`CellGraph` of a quad (F, 4) or triangle (F, 3) mesh; quads are split into triangles
    (a, b, c), (a, c, d) for rendering, as :meth:`PreparedShape.triangles` does."""
    if neighbourhood not in NEIGHBOURHOODS:
        raise ValueError(f"neighbourhood must be one of {NEIGHBOURHOODS}, got {neighbourhood!r}")
    vertices = np.asarray(vertices, dtype=np.float32)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"vertices must be (V, 3), got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] not in (3, 4):
        raise ValueError(f"faces must be (F, 3) triangles or (F, 4) quads, got {faces.shape}")
    if faces.size and (faces.min() < 0 or faces.max() >= vertices.shape[0]):
        raise ValueError(f"faces index vertices outside 0..{vertices.shape[0] - 1}")
    edges = _unique_edges(faces, neighbourhood)
    receiver = np.concatenate([edges[:, 0], edges[:, 1]])
    sender = np.concatenate([edges[:, 1], edges[:, 0]])
    degree = np.bincount(receiver, minlength=vertices.shape[0]).astype(np.float32)
    triangles = faces if faces.shape[1] == 3 else quads_to_triangles(faces)
    pos = torch.from_numpy(vertices)
    tri = torch.from_numpy(triangles)
    return CellGraph(positions=pos, normals=vertex_normals(pos, tri), triangles=tri,
                     receiver=torch.from_numpy(receiver), sender=torch.from_numpy(sender),
                     degree=torch.from_numpy(np.maximum(degree, 1.0)))


def perceive_edges(state: torch.Tensor, graph: CellGraph, order: int, nominal_valence: float,
                   angle: float | torch.Tensor = 0.0) -> torch.Tensor:
    """state (B, V, C) -> perception (B, V, K C), laid out harmonic-major ([Y_0 channels, Y_1 channels, ...]).

    The definition, as a scatter-add over the edge list: messages Y(d_ij) (s_j - s_i) summed per
    receiver, times nominal_valence / deg_i. :func:`perceive` computes the same with a sparse matrix.
    """
    b, v, c = state.shape
    basis = spherical_harmonics(graph.directions(angle), order).to(state.dtype)  # (E, K)
    diff = state[:, graph.sender] - state[:, graph.receiver]  # (B, E, C)
    messages = basis[None, :, :, None] * diff[:, :, None, :]  # (B, E, K, C)
    summed = state.new_zeros(b, v, basis.shape[1], c).index_add_(1, graph.receiver, messages)
    scale = (nominal_valence / graph.degree).to(state.dtype)[None, :, None, None]
    return (summed * scale).reshape(b, v, -1)


@dataclass
class PerceptionOperator:
    """Perception as one sparse matrix: z = M s - r * s.

    matrix (K V, V) CSR with entry (k V + i, j) = Y_k(d_ij) nominal / deg_i, row_sums (K, V). One
    sparse product replaces the gather, the scatter-add and the (B, E, K, C) message tensor of
    :func:`perceive_edges`: 4.4x faster on a CPU for 6k cells (benchmarks/bench_nca_step.py).
    """

    matrix: torch.Tensor
    row_sums: torch.Tensor

    @classmethod
    def build(cls, graph: CellGraph, order: int, nominal_valence: float, angle: float | torch.Tensor = 0.0) -> "PerceptionOperator":
        v = graph.num_cells
        basis = spherical_harmonics(graph.directions(angle), order)  # (E, K)
        k = basis.shape[1]
        values = (basis * (nominal_valence / graph.degree)[graph.receiver][:, None]).reshape(-1)
        rows = (torch.arange(k, device=basis.device)[None, :] * v + graph.receiver[:, None]).reshape(-1)
        cols = graph.sender[:, None].expand(-1, k).reshape(-1)
        with warnings.catch_warnings():  # "sparse CSR support is in beta": the product used here is stable
            warnings.simplefilter("ignore", UserWarning)
            matrix = torch.sparse_coo_tensor(torch.stack([rows, cols]), values, (k * v, v)).coalesce().to_sparse_csr()
        row_sums = torch.zeros(k * v, device=basis.device, dtype=values.dtype).index_add_(0, rows, values).reshape(k, v)
        return cls(matrix=matrix, row_sums=row_sums)

    def __call__(self, state: torch.Tensor) -> torch.Tensor:
        """state (B, V, C) -> (B, V, K C), equal to :func:`perceive_edges`."""
        b, v, c = state.shape
        k = self.row_sums.shape[0]
        x = state.permute(1, 0, 2).reshape(v, b * c)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            z = (self.matrix.to(x.dtype) @ x).reshape(k, v, b, c)
        z = z - self.row_sums.to(x.dtype).reshape(k, v, 1, 1) * x.reshape(1, v, b, c)
        return z.permute(2, 1, 0, 3).reshape(b, v, k * c)


def perceive(state: torch.Tensor, graph: CellGraph, order: int, nominal_valence: float,
             angle: float | torch.Tensor = 0.0) -> torch.Tensor:
    """:func:`perceive_edges` through the graph's cached :class:`PerceptionOperator` (one per order,
    valence and scalar angle; a per-cell angle tensor builds its operator at each call)."""
    if torch.is_tensor(angle):
        return PerceptionOperator.build(graph, order, nominal_valence, angle)(state)
    key = (order, float(nominal_valence), float(angle))
    operator = graph.operators.get(key)
    if operator is None:
        operator = graph.operators[key] = PerceptionOperator.build(graph, order, nominal_valence, angle)
    return operator(state)


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
        self.update = nn.Sequential(nn.Linear(k * cfg.channels + cfg.channels, cfg.hidden), nn.ReLU(), nn.Linear(cfg.hidden, cfg.channels))
        with torch.no_grad():  # start as the identity map, as grid NCAs do
            self.update[2].weight.zero_()
            self.update[2].bias.zero_()
        self.readout = LinearReadout(cfg.channels) if cfg.readout == "linear" else LPPNReadout(cfg.channels, cfg.lppn_hidden, cfg.lppn_frequency)

    def rule_parameters(self) -> int:
        """Parameters of the update rule alone (12,432 at the paper's sizes)."""
        return sum(p.numel() for p in self.update.parameters())

    def seed_state(self, batch: int, num_cells: int, device=None, generator: torch.Generator | None = None) -> torch.Tensor:
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

    def step(self, state: torch.Tensor, graph: CellGraph, angle: float | torch.Tensor = 0.0,
             graft: tuple["MeshNCA", torch.Tensor] | None = None, generator: torch.Generator | None = None) -> torch.Tensor:
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

    def colours(self, state: torch.Tensor, triangles: torch.Tensor, triangle_id: torch.Tensor, bary: torch.Tensor,
               sample: torch.Tensor | None = None, graft: tuple["MeshNCA", torch.Tensor] | None = None) -> torch.Tensor:
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
        return self.model.colours(self.state, self.triangles.to(device), triangle_id.to(device), bary.to(device), graft=self.graft)


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

    def __init__(self, channels: int, hidden: int, steps: int, condition: int, w_dim: int, geometry_dim: int,
                 sh_order: int = 1, update_rate: float = 0.5, nominal_valence: float = 4.0, neighbourhood: str = "edges",
                 output_init: float = 0.1):
        super().__init__()
        if steps < 1 or channels < 1 or condition < 1:
            raise ValueError("the NCA generator needs steps, channels and condition of at least 1")
        self.channels, self.steps, self.sh_order = channels, steps, sh_order
        self.update_rate, self.nominal_valence, self.neighbourhood = update_rate, nominal_valence, neighbourhood
        self.from_w = nn.Linear(w_dim, condition)
        self.from_geometry = nn.Linear(geometry_dim, condition)
        k = num_harmonics(sh_order)
        self.seed = nn.Linear(2 * condition, channels)
        self.update = nn.Sequential(nn.Linear(k * channels + channels + 2 * condition, hidden), nn.ReLU(), nn.Linear(hidden, channels))
        with torch.no_grad():
            self.update[2].weight.mul_(output_init)
            self.update[2].bias.zero_()

    def forward(self, batch, w: torch.Tensor, geometry: torch.Tensor, noise_mode: str = "random") -> torch.Tensor:
        """batch: MeshBatch; w (B, w_dim) one per shape; geometry (F_0, G) -> vertex states (V, C).

        ``noise_mode`` "none" fixes which cells fire at each step (a seeded draw), so that inference
        is deterministic; "random" draws them afresh.
        """
        check_shape(w, "ConditionedNCA: w", (batch.num_shapes, self.from_w.in_features), dtype="float")
        check_shape(geometry, "ConditionedNCA: geometry", (batch.quads.shape[0], self.from_geometry.in_features), dtype="float")
        device = w.device
        graph = build_cell_graph(batch.vertices.detach().cpu().numpy(), batch.quads.cpu().numpy(), self.neighbourhood).to(device)
        shape_of_vertex = batch.vertex_shape.to(device)
        vertex_geometry = vertex_features(geometry.to(w.dtype), batch.quads, batch.num_vertices)
        condition = torch.cat([self.from_w(w)[shape_of_vertex], self.from_geometry(vertex_geometry)], dim=1)[None]  # (1, V, 2c)
        generator = torch.Generator(device=device).manual_seed(0) if noise_mode == "none" else None
        state = self.seed(condition)
        for _ in range(self.steps):
            z = perceive(state, graph, self.sh_order, self.nominal_valence)
            ds = self.update(torch.cat([z, state, condition], dim=-1))
            fire = (torch.rand(state.shape[:2], generator=generator, device=device) < self.update_rate).to(state.dtype)[..., None]
            state = state + ds * fire
        return state[0]
