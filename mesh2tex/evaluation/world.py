"""The synthetic world's queries and their ground truth, for quality tables (loaders only; no writing).

A world from ``mesh2tex prepare synthetic`` knows everything a fair comparison needs: the photo's
camera, light and background (the query sidecar), each shape's part labels and its procedural
material (rebuilt from the world's seed, checked against ``meshes/<s>.obj``), and the baked ground
truth texture (``textured/<s>.glb``), which is the oracle of every table.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch

from mesh2tex.errors import InputError
from mesh2tex.evaluation.compare import ComparisonRender, images_to_unit, render_for_comparison
from mesh2tex.evaluation.surfaces import Surface, material_surface, textured_surface
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.io.images import load_image, load_mask
from mesh2tex.render import RenderSettings, crop_mask, object_box, orbit_camera, rasterize, transform_points
from mesh2tex.synthetic.world import WorldSpec
from mesh2tex.transfer.photo import FramedView


@dataclass
class Query:
    """One held-out query photo of the world and its ground truth."""

    name: str  # file stem, e.g. chair_0004_00
    image: Path
    mask: Path
    shape: str  # the world shape it shows
    azimuth: float
    elevation: float
    distance: float
    fov: float
    record: dict = field(default_factory=dict)  # the sidecar (camera, light, background, files)


@dataclass
class World:
    root: Path
    index: dict
    queries: list[Query]
    query_shapes: list[str]


# ------------------------------------------------------------------------------------------ queries
def load_world(root: str | Path, max_queries: int = 0) -> World:
    """The world's index and its query photos (first ``max_queries``; 0: all) with their sidecar poses."""
    root = Path(root)
    index_path = root / "index.json"
    if not index_path.is_file():
        raise InputError(f"{root}: not a synthetic world (no index.json; make one with 'mesh2tex prepare synthetic')")
    try:
        index = json.loads(index_path.read_text())
    except json.JSONDecodeError as error:
        raise InputError(f"{index_path}: not valid JSON ({error.msg})") from None
    if index.get("format") != "mesh2tex-synthetic-world":
        raise InputError(f"{index_path}: not a mesh2tex synthetic world index (format {index.get('format')!r})")
    if not index.get("complete", False):
        raise InputError(f"{root}: the world is incomplete; finish it with 'mesh2tex prepare synthetic' (it resumes)")
    entries = index.get("queries") or []
    if not entries:
        raise InputError(f"{index_path}: the world has no query photos (prepare it with --query-views above 0)")
    queries = []
    for entry in entries:
        sidecar = root / entry["sidecar"] if "sidecar" in entry else None
        truth = json.loads(sidecar.read_text()) if sidecar is not None and sidecar.is_file() else entry
        image, mask = root / entry["image"], root / entry["mask"]
        for path in (image, mask):
            if not path.is_file():
                raise InputError(f"{path}: query file missing (listed in {index_path})")
        queries.append(
            Query(
                name=image.stem,
                image=image,
                mask=mask,
                shape=truth["shape"],
                azimuth=float(truth["azimuth"]),
                elevation=float(truth["elevation"]),
                distance=float(truth["distance"]),
                fov=float(truth["fov"]),
                record=truth,
            )
        )
    if max_queries > 0:
        queries = queries[:max_queries]
    query_shapes = list(dict.fromkeys(q.shape for q in queries))
    return World(root=root, index=index, queries=queries, query_shapes=query_shapes)


def other_shape_name(name: str, available: list[str]) -> str:
    """The transfer target for a query of shape ``name``: the next available shape by name (cyclic), never ``name``."""
    others = sorted(set(available) - {name})
    if not others:
        raise InputError(f"transfer to another shape needs a second prepared shape besides {name}")
    later = [n for n in others if n > name]
    return later[0] if later else others[0]


@torch.no_grad()
def photo_frame_view(shape: PreparedShape, query: Query, resolution: int, margin: float) -> FramedView:
    """The query's true camera, framed like its photo crop: a :class:`mesh2tex.transfer.FramedView` whose render,
    cropped with the photo's own box, is pixel-aligned with the cropped photo (exact geometry).

    Its ``mask`` (1,1,R,R) is where the shape covers the crop; its ``noc`` is left empty.
    """
    photo_mask = np.asarray(load_mask(query.mask), dtype=bool)
    side = photo_mask.shape[0]
    if photo_mask.shape[1] != side:
        raise InputError(
            f"{query.mask}: query photos must be square to be framed like renders, got {photo_mask.shape[1]}x{side}"
        )
    if not photo_mask.any():
        raise InputError(f"{query.mask}: the query's object mask is empty")
    box = object_box(photo_mask, margin)
    camera = orbit_camera(
        torch.tensor([query.azimuth]), torch.tensor([query.elevation]), distance=query.distance, fov=query.fov
    )
    vertices = torch.as_tensor(shape.vertices[0], dtype=torch.float32)
    raster = rasterize(transform_points(vertices, camera.mvp), torch.as_tensor(shape.triangles(0)), (side, side))
    mask = crop_mask(raster.face_id[0] >= 0, box, resolution)
    return FramedView(
        mvp=camera.mvp,
        render_size=side,
        box=box,
        noc=torch.zeros(resolution, resolution, 3),
        mask=mask,
        azimuth=float(query.azimuth),
        elevation=float(query.elevation),
    )


# ------------------------------------------------------------------------------------- ground truth
@dataclass
class ShapeTruth:
    """One world shape: ``shape`` (a ``SyntheticShape``: vertices, faces, face_parts), its ``material``
    and ``oracle``, the baked ground truth GLB as a :class:`Surface` with the shape's part labels."""

    name: str
    shape: object
    material: object
    oracle: Surface

    def material_on(self, other: "ShapeTruth") -> Surface:
        """This shape's material on ``other``'s mesh, parts matched by label: the ground truth of a
        transfer of this shape's photo to ``other``."""
        return material_surface(other.shape.vertices, other.shape.faces, other.shape.face_parts, self.material)

    @property
    def exact(self) -> Surface:
        """The material on the shape itself (what the world's photos show, before any baking)."""
        return self.material_on(self)


@dataclass
class QueryTruth:
    """A query photo and its ground truth.

    name   file stem (``chair_0009_00``); view the sidecar's camera, light and background
    photo  [1, 3, R, R] float32 in [0, 1]; photo_mask [1, 1, R, R] {0, 1}; R = the world's resolution
    truth  the query shape's :class:`ShapeTruth`
    photo_render  how the world rendered the photo (its resolution is R)
    """

    name: str
    view: object
    photo: torch.Tensor
    photo_mask: torch.Tensor
    truth: ShapeTruth
    photo_render: RenderSettings

    @property
    def resolution(self) -> int:
        return int(self.photo.shape[-1])

    def render_settings(self, lighting: str = "photo") -> RenderSettings:
        """The photo's render settings with ``lighting`` ("photo" or "albedo"): what every render compared with it
        uses."""
        return replace(self.photo_render, lighting=lighting)


def world_spec(index: dict):
    """The ``WorldSpec`` of a world's ``index.json`` (its ``settings``)."""
    settings = {k: v for k, v in index.get("settings", {}).items() if k in WorldSpec.__dataclass_fields__}
    return WorldSpec(**settings)


def _shape_index(name: str) -> int:
    try:
        return int(name.rsplit("_", 1)[1])
    except (IndexError, ValueError):
        raise ValueError(f"{name!r} is not a world shape name (category_NNNN)") from None


def load_shape_truth(root: str | Path, index: dict, name: str) -> ShapeTruth:
    """The ground truth of world shape ``name``: rebuilt from the world's seed, checked against
    ``meshes/<name>.obj`` and ``textured/<name>.glb`` (ValueError naming the file if they disagree)."""
    return _load_shape_truth(str(Path(root).resolve()), json.dumps(index.get("settings", {}), sort_keys=True), name)


@lru_cache(maxsize=32)
def _load_shape_truth(root: str, settings: str, name: str) -> ShapeTruth:
    from mesh2tex.geometry.mesh_io import load_mesh
    from mesh2tex.io.assets import load_glb
    from mesh2tex.synthetic.world import make_material, make_shape

    spec = world_spec({"settings": json.loads(settings)})
    index = _shape_index(name)
    shape = make_shape(spec, index)
    obj = Path(root) / "meshes" / f"{name}.obj"
    vertices, faces = load_mesh(obj)
    if faces.shape != shape.faces.shape or not np.allclose(vertices[faces], shape.vertices[shape.faces], atol=1e-5):
        raise ValueError(f"{obj}: differs from the shape the world's settings make (a world of another version?)")
    glb = Path(root) / "textured" / f"{name}.glb"
    glb_vertices, glb_faces, uv, image = load_glb(glb)
    if glb_faces.shape != shape.faces.shape or not np.allclose(
        glb_vertices[glb_faces], shape.vertices[shape.faces], atol=1e-4
    ):
        raise ValueError(f"{glb}: its faces do not follow the order of {obj}")
    oracle = textured_surface(glb_vertices, glb_faces, uv, image, shape.face_parts)
    return ShapeTruth(name=name, shape=shape, material=make_material(spec, index), oracle=oracle)


def load_query_truth(root: str | Path, index: dict, sidecar: dict) -> QueryTruth:
    """A query (its sidecar, as in ``index["queries"]`` or ``queries/<q>.json``) and its ground truth."""
    from mesh2tex.synthetic.world import PhotoSetup

    root = Path(root)
    view = PhotoSetup(
        **{k: (tuple(sidecar[k]) if k == "light" else sidecar[k]) for k in PhotoSetup.__dataclass_fields__}
    )
    rgb, _ = load_image(root / sidecar["image"])
    mask = np.asarray(load_mask(root / sidecar["mask"]), dtype=bool)
    photo = images_to_unit(rgb)
    name = Path(sidecar["image"]).stem
    # rendered as the world renders its photos, at the photo's own size
    photo_render = RenderSettings(int(photo.shape[-1]), world_spec(index).supersample)
    return QueryTruth(
        name=name,
        view=view,
        photo=photo,
        photo_mask=torch.from_numpy(mask)[None, None].float(),
        truth=load_shape_truth(root, index, sidecar["shape"]),
        photo_render=photo_render,
    )


def reference_renders(query: QueryTruth, views: list, lighting: str = "photo") -> ComparisonRender:
    """What the world would photograph at ``views``: the query shape's material rendered by
    :func:`render_for_comparison` as the photo was; where a view is the photo's own and ``lighting`` is
    "photo", the photo file itself (the same image up to 8-bit rounding)."""
    render = render_for_comparison(query.truth.exact, views, query.render_settings(lighting))
    if lighting == "photo":
        for b, view in enumerate(views):
            if view == query.view:
                render.rgb[b] = query.photo[0]
                render.mask[b] = query.photo_mask[0]
    return render


@dataclass
class WorldData:
    """A world as the generation protocol reads it: its spec and the names of its shapes by split."""

    spec: WorldSpec
    root: Path
    held_out: list[str]  # shape names
    train: list[str]  # the training shapes' names
    indices: dict[str, int]  # shape name -> world index


def read_world(root: str | Path) -> WorldData:
    """The world's spec, its held-out shapes (the query split) and its training shapes from ``root/index.json``."""
    world = load_world(root)  # checks the index (format, complete, query files)
    spec = world_spec(world.index)
    held_out = list(world.index["split"]["query_shapes"])
    if not held_out:
        raise InputError(f"{world.root / 'index.json'}: the world holds no held-out shapes")
    return WorldData(
        spec=spec,
        root=world.root,
        held_out=held_out,
        train=list(world.index["split"]["train_shapes"]),
        indices={spec.shape_name(i): i for i in range(spec.shapes)},
    )
