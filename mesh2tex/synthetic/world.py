"""The synthetic world: procedural shapes, their ground-truth textures, "photos" of them and held-out queries.

Pure functions; the stage ``data_prep/synthetic.py`` (``mesh2tex prepare synthetic``) writes the files.
Everything is drawn from ``numpy.random.default_rng([seed, category, shape index, stream])``, so a
shape, its material and its views do not depend on how many shapes the world holds or on the order
in which they are built (a resumed run makes the same files).

Cameras follow ``mesh2tex.render.orbit_camera`` (y up, degrees; the object's front faces +z, so
azimuth 0 sees the front). Meshes live in the normalised frame (bbox centre 0, diagonal 1), and the
NOC of a surface point is its position + 0.5, in [0, 1]^3 (``mesh2tex.geometry.features.noc_coordinates``,
the NOC of prepared shapes).
"""

from __future__ import annotations

import colorsys
import functools
import math
from dataclasses import asdict, dataclass, replace

import numpy as np
import torch

from mesh2tex.render import (
    LightConfig,
    RenderSettings,
    composite,
    dilate_texture,
    face_attribute,
    face_normals,
    interpolate,
    orbit_camera,
    rasterize,
    render_noc,
    shade_lambert,
    transform_points,
    unwrap_uv,
    uv_rasterize,
)
from mesh2tex.synthetic.materials import Material, fractal_noise, random_material
from mesh2tex.synthetic.real_materials import real_material
from mesh2tex.synthetic.shapes import CATEGORIES, SyntheticShape
from mesh2tex.synthetic.variety import VARIETIES, generate_varied_shape

# Random streams of one shape (the last entry of the rng seed sequence).
_SHAPE, _MATERIAL, _PHOTOS, _QUERIES = 0, 1, 2, 3
BACKGROUND_KINDS = ("solid", "gradient", "noise", "photo")
# The photos' lights; the GAN's light prior (LightConfig's defaults) is the same distribution.
PHOTO_LIGHTS = LightConfig()
BACKGROUND_PHOTOS = (  # scikit-image photographs the world's "photo" backgrounds and the mask network's backdrops crop
    "coffee",
    "rocket",
    "hubble_deep_field",
    "immunohistochemistry",
    "brick",
    "grass",
    "gravel",
)


@dataclass(frozen=True)
class WorldSpec:
    """Everything that determines a world; two equal specs give identical files."""

    category: str = "chair"  # 'chair' or 'car'
    shapes: int = 12  # shapes in meshes/ (training shapes plus query shapes)
    views: int = 8  # photos per training shape in images/
    seed: int = 0  # master seed
    resolution: int = 128  # photo and query size in pixels (square)
    query_shapes: int = 0  # shapes held out for queries/; 0 means a quarter of the shapes (at least 1)
    query_views: int = 2  # query photos per held-out shape
    elevation_min: float = 5.0  # degrees
    elevation_max: float = 35.0  # degrees
    distance_min: float = 1.5  # camera distance range, in units of the shape's bbox diagonal
    distance_max: float = 1.9
    fov: float = 40.0  # vertical field of view, degrees
    supersample: int = 2  # render at this multiple of the resolution and average (anti-aliasing)
    texture_size: int = 512  # side of the baked UV texture of textured/*.glb
    # 'boxy' (the original shapes) or 'real' (families of real chairs and cars, mesh2tex.synthetic.variety)
    variety: str = "boxy"

    def __post_init__(self):
        if self.category not in CATEGORIES:
            raise ValueError(f"category must be one of {', '.join(CATEGORIES)}, got {self.category!r}")
        if self.variety not in VARIETIES:
            raise ValueError(f"variety must be one of {', '.join(VARIETIES)}, got {self.variety!r}")
        _ = self.photo_render  # checks resolution and supersample

    @property
    def photo_render(self) -> RenderSettings:
        """How the world's photos and queries are rendered (lit, supersampled): every render compared with them uses
        it."""
        return RenderSettings(self.resolution, self.supersample)

    @property
    def query_count(self) -> int:
        return self.query_shapes if self.query_shapes > 0 else max(1, round(self.shapes / 4))

    def split(self) -> tuple[list[int], list[int]]:
        """(training shape indices, query shape indices): the last ``query_count`` shapes are held out."""
        train = self.shapes - self.query_count
        return list(range(train)), list(range(train, self.shapes))

    def shape_name(self, index: int) -> str:
        return f"{self.category}_{index:04d}"

    def rng(self, index: int, stream: int) -> np.random.Generator:
        return np.random.default_rng([self.seed, CATEGORIES.index(self.category), index, stream])

    def to_dict(self) -> dict:
        """The settings as JSON; a boxy world leaves ``variety`` out, so its index is what it was before varieties
        existed."""
        settings = asdict(self)
        if self.variety == "boxy":
            del settings["variety"]
        return settings


@dataclass(frozen=True)
class PhotoSetup:
    """One photo's camera, light and background (JSON-serialisable via ``asdict``)."""

    azimuth: float  # degrees
    elevation: float  # degrees
    distance: float
    fov: float  # degrees, vertical
    light: tuple[float, float, float]  # unit direction towards the light, world space
    ambient: float  # share of light that does not depend on the normal
    background: str  # one of BACKGROUND_KINDS
    background_seed: int


def make_shape(spec: WorldSpec, index: int) -> SyntheticShape:
    return generate_varied_shape(spec.category, spec.rng(index, _SHAPE), spec.variety)


def make_material(spec: WorldSpec, index: int, shape: SyntheticShape | None = None) -> Material:
    """Shape ``index``'s ground-truth material; the varied world sizes it to the shape (``shape``, made again when
    None)."""
    if spec.variety == "real" and shape is None:
        shape = make_shape(spec, index)
    return sample_material(spec, spec.rng(index, _MATERIAL), shape)


def sample_material(spec: WorldSpec, rng: np.random.Generator, shape: SyntheticShape | None = None) -> Material:
    """A material of the world's sampler drawn from ``rng``: the boxy world's procedural library, or for
    ``variety: real`` materials a photo would show (:mod:`mesh2tex.synthetic.real_materials`), at
    ``shape``'s physical scale and chosen for its family (typical sizes when None)."""
    if spec.variety == "real":
        return real_material(spec.category, rng, shape)
    return random_material(spec.category, rng)


def sample_views(spec: WorldSpec, index: int, count: int, query: bool = False) -> list[PhotoSetup]:
    """``count`` random views of shape ``index`` (photos, or queries when ``query``)."""
    rng = spec.rng(index, _QUERIES if query else _PHOTOS)
    views = []
    for _ in range(count):
        azimuth = float(rng.uniform(0.0, 360.0))
        elevation = float(rng.uniform(spec.elevation_min, spec.elevation_max))
        distance = float(rng.uniform(spec.distance_min, spec.distance_max))
        # Light from the camera's side and above, never from behind the object: mild, readable shading.
        az = math.radians(azimuth + rng.uniform(-PHOTO_LIGHTS.azimuth_spread, PHOTO_LIGHTS.azimuth_spread))
        el = math.radians(rng.uniform(PHOTO_LIGHTS.elevation_min, PHOTO_LIGHTS.elevation_max))
        light = (math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az))
        views.append(
            PhotoSetup(
                azimuth=round(azimuth, 4),
                elevation=round(elevation, 4),
                distance=round(distance, 4),
                fov=spec.fov,
                light=tuple(round(v, 5) for v in light),
                ambient=round(float(rng.uniform(PHOTO_LIGHTS.ambient_min, PHOTO_LIGHTS.ambient_max)), 4),
                background=BACKGROUND_KINDS[int(rng.integers(len(BACKGROUND_KINDS)))],
                background_seed=int(rng.integers(1 << 31)),
            )
        )
    return views


# ----------------------------------------------------------------------------------------------
# Rendering


def render_views(
    shape: SyntheticShape,
    material: Material | None,
    views: list[PhotoSetup],
    settings: RenderSettings,
    *,
    vertex_colours: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Render ``views`` of the textured shape over their backgrounds, as ``settings`` say (the world's
    photos: :attr:`WorldSpec.photo_render`); ``lighting="albedo"`` renders every view with ambient 1.

    The albedo is ``material`` evaluated at each covered pixel's surface point or, when
    ``vertex_colours`` (V, 3) float in [0, 1], one per vertex of ``shape.vertices``, is given, those
    colours interpolated with the raster's barycentrics (``material`` may then be None). Shading,
    backgrounds, NOC and mask do not depend on the albedo's source.

    Returns uint8 arrays: ``rgb`` (B, R, R, 3), ``mask`` (B, R, R) 0/255, ``noc`` (B, R, R, 3) (NOC * 255,
    0 on background), with R = ``settings.resolution``. Rendering happens at ``settings.raster_side`` and
    is box-filtered down; the mask is coverage >= 1/2.
    """
    if material is None and vertex_colours is None:
        raise ValueError("render_views needs a material or vertex_colours")
    if vertex_colours is not None and np.shape(vertex_colours) != (len(shape.vertices), 3):
        raise ValueError(
            f"vertex_colours must be ({len(shape.vertices)}, 3), one per vertex, got {np.shape(vertex_colours)}"
        )
    if not settings.lit:
        views = [replace(v, ambient=1.0) for v in views]
    big = settings.raster_side
    vertices = torch.as_tensor(shape.vertices, dtype=torch.float32)
    faces = torch.as_tensor(shape.faces, dtype=torch.int64)
    normals_per_face = face_normals(vertices, faces)
    parts = torch.as_tensor(shape.face_parts)
    camera = orbit_camera(
        torch.tensor([v.azimuth for v in views]),
        torch.tensor([v.elevation for v in views]),
        distance=torch.tensor([v.distance for v in views]),
        fov=torch.tensor([v.fov for v in views]),
    )
    raster = rasterize(transform_points(vertices, camera.mvp), faces, (big, big))
    covered = raster.face_id >= 0  # (B, H, W)
    points = interpolate(vertices, raster, faces)  # (B, H, W, 3)
    normals = face_attribute(normals_per_face, raster)  # (B, H, W, 3), flat: the shapes are faceted

    albedo = torch.zeros(covered.shape + (3,), dtype=torch.float32)
    if vertex_colours is not None:
        albedo = interpolate(torch.as_tensor(vertex_colours, dtype=torch.float32), raster, faces)  # 0 on background
    elif covered.any():
        colours = material(
            points[covered].double().numpy(), normals[covered].double().numpy(), parts[raster.face_id[covered]].numpy()
        )
        albedo[covered] = torch.as_tensor(colours, dtype=torch.float32)
    light = torch.tensor([v.light for v in views], dtype=torch.float32)
    ambient = torch.tensor([v.ambient for v in views], dtype=torch.float32)
    shaded = shade_lambert(albedo, normals, light, ambient[:, None, None, None])
    background = torch.stack([torch.as_tensor(random_background(v.background, v.background_seed, big)) for v in views])
    mask = covered[..., None].float()
    rgb = composite(shaded, mask, background)
    noc = render_noc(torch.as_tensor(shape.noc), raster, faces)

    rgb, coverage, noc = (settings.down_channels_last(t) for t in (rgb, mask, noc))
    noc = noc / coverage.clamp_min(1e-6)  # the mean NOC of the covered sub-pixels
    keep = coverage >= 0.5
    return {
        "rgb": unit_to_uint8(rgb),
        "mask": (keep[..., 0].numpy().astype(np.uint8) * 255),
        "noc": unit_to_uint8(noc * keep),
    }


def unit_to_uint8(image: torch.Tensor) -> np.ndarray:
    """Colours in [0, 1] (any shape) -> uint8 numpy, rounded."""
    return (image.clamp(0, 1) * 255 + 0.5).to(torch.uint8).numpy()


def random_background(kind: str, seed: int, size: int) -> np.ndarray:
    """A (size, size, 3) float32 background in [0, 1]: solid, vertical gradient, noise, or a blurred photo crop."""
    rng = np.random.default_rng(seed)

    def colour() -> np.ndarray:  # muted colours, like walls and floors
        return np.array(colorsys.hsv_to_rgb(rng.uniform(0, 1), rng.uniform(0.0, 0.45), rng.uniform(0.3, 0.95)))

    if kind == "solid":
        image = np.broadcast_to(colour(), (size, size, 3))
    elif kind == "gradient":
        t = np.linspace(0, 1, size)[:, None, None]
        image = np.broadcast_to(colour() * (1 - t) + colour() * t, (size, size, 3))
    elif kind == "noise":
        ys, xs = np.meshgrid(np.linspace(0, 1, size), np.linspace(0, 1, size), indexing="ij")
        points = np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, rng.uniform(0, 100))], axis=1) * rng.uniform(2, 6)
        t = fractal_noise(points, 3, int(rng.integers(1 << 16))).reshape(size, size, 1)
        image = colour() * (1 - t) + colour() * t
    elif kind == "photo":
        image = _photo_crop(rng, size)
    else:
        raise ValueError(f"unknown background kind {kind!r}")
    return np.ascontiguousarray(image, dtype=np.float32)


def _photo_crop(rng: np.random.Generator, size: int) -> np.ndarray:
    from PIL import Image, ImageFilter

    source = background_photo(BACKGROUND_PHOTOS[int(rng.integers(len(BACKGROUND_PHOTOS)))])
    h, w = source.shape[:2]
    side = int(rng.uniform(0.4, 1.0) * min(h, w))
    top, left = int(rng.integers(0, h - side + 1)), int(rng.integers(0, w - side + 1))
    crop = Image.fromarray(source[top : top + side, left : left + side]).resize((size, size), Image.BILINEAR)
    crop = crop.filter(ImageFilter.GaussianBlur(radius=size / 96))  # out of focus, like a photo's backdrop
    image = np.asarray(crop, dtype=np.float32) / 255.0
    if rng.random() < 0.5:
        image = image[:, ::-1]
    return image * rng.uniform(0.7, 1.1) + rng.uniform(-0.05, 0.1)


@functools.lru_cache(maxsize=8)
def background_photo(name: str) -> np.ndarray:
    """A bundled scikit-image photo as (H, W, 3) uint8 (grayscale ones repeated to three channels)."""
    import skimage.data

    image = np.asarray(getattr(skimage.data, name)())
    if image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=2)
    return np.ascontiguousarray(image[..., :3])


# ----------------------------------------------------------------------------------------------
# Texture baking


@dataclass
class BakedMesh:
    """A mesh ready for ``save_glb``: vertices (V', 3) float32 split on UV seams, faces (T, 3) int64,
    uv (V', 2) float32 (v up), texture (S, S, 3) uint8."""

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    texture: np.ndarray


def bake_material(shape: SyntheticShape, material: Material, size: int = 512, padding: int = 4) -> BakedMesh:
    """Unwrap the shape (xatlas) and evaluate ``material`` at every texel's surface point.

    Texels outside the charts are filled by dilating the charts ``padding`` pixels, so bilinear
    lookups and mipmaps at chart borders do not bleed in a background colour.
    """
    vertices, faces, uv, _ = unwrap_uv(shape.vertices, shape.faces)
    vertices_t = torch.as_tensor(np.asarray(vertices), dtype=torch.float32)
    faces_t = torch.as_tensor(np.asarray(faces), dtype=torch.int64)
    uv_t = torch.as_tensor(np.asarray(uv), dtype=torch.float32)
    raster = uv_rasterize(uv_t, faces_t, (size, size))
    covered = raster.face_id[0] >= 0  # (S, S)
    points = interpolate(vertices_t, raster, faces_t)[0]
    normals_per_face = face_normals(vertices_t, faces_t)  # unwrap keeps the face order, so parts still apply
    image = torch.zeros(size, size, 3)
    if covered.any():
        ids = raster.face_id[0][covered]
        colours = material(
            points[covered].double().numpy(), normals_per_face[ids].double().numpy(), shape.face_parts[ids.numpy()]
        )
        image[covered] = torch.as_tensor(colours, dtype=torch.float32)
    image = dilate_texture(image.permute(2, 0, 1), covered, padding).permute(1, 2, 0)
    return BakedMesh(vertices_t.numpy(), faces_t.numpy(), uv_t.numpy(), unit_to_uint8(image))


# ----------------------------------------------------------------------------------------------
# Contact sheet


def contact_sheet(images: list[np.ndarray], columns: int, gap: int = 2, fill: int = 255) -> np.ndarray:
    """Tile equally sized (H, W, 3) uint8 images row by row into one (rows*(H+gap)-gap, ...) uint8 image."""
    if not images:
        raise ValueError("contact_sheet needs at least one image")
    h, w = images[0].shape[:2]
    rows = math.ceil(len(images) / columns)
    sheet = np.full((rows * (h + gap) - gap, columns * (w + gap) - gap, 3), fill, dtype=np.uint8)
    for k, image in enumerate(images):
        r, c = divmod(k, columns)
        sheet[r * (h + gap) : r * (h + gap) + h, c * (w + gap) : c * (w + gap) + w] = image[..., :3]
    return sheet
