"""Orbit cameras: the one camera model used by training, rendering, pose bins and evaluation.

Convention (documented in docs/rendering.md):
  * World space is right-handed with **y up**; the object sits at the origin.
  * A camera at azimuth ``az`` and elevation ``el`` (both in **degrees**) and distance ``d`` sits at
    ``d * (cos(el) sin(az), sin(el), cos(el) cos(az))`` and looks at the origin. Azimuth 0, elevation 0
    looks down the -z axis from +z; azimuth 90 sits on +x; elevation 90 looks straight down.
  * Camera (eye) space is OpenGL's: x right, y up, the camera looks down -z. The camera's right axis is
    ``(cos az, 0, -sin az)``, which stays defined at the poles (elevation +-90).
  * ``proj`` is the OpenGL perspective matrix with a vertical field of view ``fov`` (degrees), so clip
    space is OpenGL's: after division by w, x, y, z in [-1, 1] are visible, z = -1 on the near plane.
  * Row-vector-free: points are columns, ``clip = mvp @ [x, y, z, 1]``; ``mvp = proj @ view`` (the model
    matrix is the identity: meshes are placed in world space by the caller).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from mesh2tex.checks import check_shape
from mesh2tex.config import check_fields

# world units; a unit-sized object fills most of the frame at the default fov (the GAN's own camera: CameraConfig)
DEFAULT_DISTANCE = 2.5
DEFAULT_FOV = 40.0  # vertical field of view in degrees
DEFAULT_NEAR = 0.1
DEFAULT_FAR = 100.0


@dataclass
class CameraConfig:
    """The texture GAN's cameras: the random training views, and the camera its textures are shown and
    transferred with (a GAN checkpoint keeps it in ``config.camera``; :func:`mesh2tex.models.TrainedGenerator`)."""

    distance: float = 1.7  # camera distance from the origin (shapes have a bounding-box diagonal of 1)
    fov: float = 40.0  # vertical field of view, degrees
    elevation_min: float = 5.0  # lowest elevation of the random views, degrees
    elevation_max: float = 35.0  # highest elevation of the random views, degrees
    jitter_degrees: float = 2.0  # std of the Gaussian noise added to azimuth and elevation
    distance_jitter: float = 0.06  # relative std of the Gaussian noise on the distance

    def __post_init__(self):
        check_fields(
            self,
            positive=("distance",),
            between={
                "fov": (1.0, 179.0),
                "elevation_min": (-90.0, 90.0),
                "elevation_max": (-90.0, 90.0),
                "jitter_degrees": (0.0, 90.0),
                "distance_jitter": (0.0, 0.5),
            },
        )
        if self.elevation_min > self.elevation_max:
            raise ValueError(f"elevation_min {self.elevation_min} is above elevation_max {self.elevation_max}")


@dataclass
class NCACameraConfig:
    """The cameras of a mesh automaton (``train nca``): around a mesh scaled into the unit ball; ``infer nca``
    frames its renders with the training's distance and field of view."""

    distance: float = 3.2  # in units of the mesh's radius (meshes are scaled into the unit ball)
    fov: float = 40.0  # vertical field of view, degrees
    elevation_min: float = -60.0  # random views: elevation range, degrees
    elevation_max: float = 60.0

    def __post_init__(self):
        check_fields(
            self,
            positive=("distance",),
            between={"fov": (1.0, 179.0), "elevation_min": (-90.0, 90.0), "elevation_max": (-90.0, 90.0)},
        )
        if self.elevation_max < self.elevation_min:
            raise ValueError(f"elevation_max {self.elevation_max} is below elevation_min {self.elevation_min}")


@dataclass
class Camera:
    """A batch of B cameras.

    Attributes:
        view: (B,4,4) float32, world -> eye space.
        proj: (B,4,4) float32, eye -> OpenGL clip space.
        mvp: (B,4,4) float32, ``proj @ view``.
        position: (B,3) float32, camera centre in world space.
    """

    view: torch.Tensor
    proj: torch.Tensor
    mvp: torch.Tensor
    position: torch.Tensor

    def __len__(self) -> int:
        return self.mvp.shape[0]

    def to(self, device) -> "Camera":
        return Camera(*(t.to(device) for t in (self.view, self.proj, self.mvp, self.position)))


def _as_batch(value, device, dtype=torch.float32) -> torch.Tensor:
    """A Python float, 0-d or (B,) tensor -> (B,) tensor."""
    t = torch.as_tensor(value, dtype=dtype, device=device)
    return t.reshape(-1)


def perspective(fov, near=DEFAULT_NEAR, far=DEFAULT_FAR, aspect=1.0, device=None) -> torch.Tensor:
    """OpenGL perspective projection(s).

    Args:
        fov: vertical field of view in degrees, float or (B,) tensor.
        near, far: positive clip distances (floats or (B,) tensors).
        aspect: width / height of the image.
    Returns:
        (B,4,4) float32.
    """
    fov = _as_batch(fov, device)
    near = _as_batch(near, fov.device)
    far = _as_batch(far, fov.device)
    aspect = _as_batch(aspect, fov.device)
    B = max(fov.numel(), near.numel(), far.numel(), aspect.numel())
    fov, near, far, aspect = (t.expand(B) for t in (fov, near, far, aspect))
    focal = 1.0 / torch.tan(torch.deg2rad(fov) * 0.5)
    proj = torch.zeros(B, 4, 4, dtype=torch.float32, device=fov.device)
    proj[:, 0, 0] = focal / aspect
    proj[:, 1, 1] = focal
    proj[:, 2, 2] = (far + near) / (near - far)
    proj[:, 2, 3] = 2.0 * far * near / (near - far)
    proj[:, 3, 2] = -1.0
    return proj


def _check_batch_args(function: str, **values) -> None:
    """Tensor arguments of an orbit camera are 0-d, (1,) or (B,) with one B; floats pass unchecked."""
    sizes: dict[str, tuple[int, str]] = {}
    for name, value in values.items():
        if torch.is_tensor(value):
            check_shape(value, f"{function}: {name}", (), (1,), ("B",), sizes=sizes)


def orbit_direction(azimuth: torch.Tensor, elevation: torch.Tensor) -> torch.Tensor:
    """Unit vectors (B, 3) from the origin towards ``azimuth``/``elevation`` (B,) degrees: an orbit
    camera's eye direction, and the direction of a light placed the same way."""
    check_shape(
        elevation,
        "orbit_direction: elevation",
        ("B",),
        sizes=check_shape(azimuth, "orbit_direction: azimuth", ("B",), dtype="float"),
        dtype="float",
    )
    az, el = torch.deg2rad(azimuth), torch.deg2rad(elevation)
    return torch.stack([el.cos() * az.sin(), el.sin(), el.cos() * az.cos()], dim=-1)


def orbit_camera(
    azimuth,
    elevation,
    distance=DEFAULT_DISTANCE,
    fov=DEFAULT_FOV,
    near=DEFAULT_NEAR,
    far=DEFAULT_FAR,
    aspect=1.0,
) -> Camera:
    """Batched orbit cameras looking at the origin (see the module docstring for the convention).

    Args:
        azimuth: degrees, float or (B,) tensor (a 0-d or (1,) tensor counts as a float).
        elevation: degrees, float or (B,) tensor, in [-90, 90].
        distance: float or (B,) tensor, distance from the origin.
        fov: vertical field of view in degrees, float or (B,) tensor.
        near, far: clip distances, floats or (B,) tensors.
        Tensor arguments of length B must agree on B (ValueError naming the argument otherwise).
        aspect: image width / height.
    Returns:
        Camera with (B,4,4) ``view``, ``proj``, ``mvp`` and (B,3) ``position``, float32, on the device
        of ``azimuth`` when it is a tensor (else CPU). Scalars broadcast against (B,) tensors.
    """
    _check_batch_args(
        "orbit_camera", azimuth=azimuth, elevation=elevation, distance=distance, fov=fov, near=near, far=far
    )
    device = next((t.device for t in (azimuth, elevation, distance, fov) if torch.is_tensor(t)), None)
    az_deg, el_deg = _as_batch(azimuth, device), _as_batch(elevation, device)
    dist = _as_batch(distance, device)
    B = max(az_deg.numel(), el_deg.numel(), dist.numel(), _as_batch(fov, device).numel())
    az_deg, el_deg, dist = az_deg.expand(B), el_deg.expand(B), dist.expand(B)
    az = torch.deg2rad(az_deg)

    back = orbit_direction(az_deg, el_deg)  # eye +z axis
    position = dist[:, None] * back
    right = torch.stack([az.cos(), torch.zeros_like(az), -az.sin()], dim=-1)
    up = torch.linalg.cross(back, right)

    view = torch.zeros(B, 4, 4, dtype=torch.float32, device=az.device)
    view[:, 0, :3], view[:, 1, :3], view[:, 2, :3] = right, up, back
    view[:, 0, 3] = -(right * position).sum(-1)
    view[:, 1, 3] = -(up * position).sum(-1)
    view[:, 2, 3] = -(back * position).sum(-1)
    view[:, 3, 3] = 1.0

    proj = perspective(fov, near, far, aspect, device=az.device).expand(B, 4, 4).contiguous()
    return Camera(view=view, proj=proj, mvp=proj @ view, position=position)


def turntable_angles(k: int, elevation: float = 20.0, start: float = 0.0) -> tuple[torch.Tensor, torch.Tensor]:
    """Azimuths evenly spaced over the circle from ``start`` (k,) and a fixed elevation (k,), in degrees."""
    return torch.arange(k, dtype=torch.float32) * (360.0 / k) + start, torch.full((k,), float(elevation))


def transform_points(vertices: torch.Tensor, mvp: torch.Tensor) -> torch.Tensor:
    """Project world-space points to homogeneous clip space.

    Args:
        vertices: (V,3) shared by all views, or (B,V,3), float.
        mvp: (B,4,4) or (4,4) float; a batch of 1 (vertices or mvp) broadcasts over the other's B.
    Returns:
        (B,V,4) clip-space positions, the ``pos`` input of :func:`mesh2tex.render.rasterize`.
        Differentiable with respect to both inputs.
    """
    sizes = check_shape(vertices, "transform_points: vertices", ("V", 3), ("B", "V", 3), dtype="float")
    if sizes.get("B", (None,))[0] == 1:
        del sizes["B"]  # one set of vertices broadcasts over every camera
    check_shape(mvp, "transform_points: mvp", (4, 4), (1, 4, 4), ("B", 4, 4), sizes=sizes, dtype="float")
    if mvp.dim() == 2:
        mvp = mvp[None]
    homogeneous = torch.cat([vertices, torch.ones_like(vertices[..., :1])], dim=-1)
    if homogeneous.dim() == 2:
        return torch.einsum("bij,vj->bvi", mvp.to(homogeneous.dtype), homogeneous)
    return torch.einsum("bij,bvj->bvi", mvp.to(homogeneous.dtype), homogeneous)
