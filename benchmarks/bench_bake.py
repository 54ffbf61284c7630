"""The texture baked onto the user's own mesh: how faithful it is, how long it takes, how much memory.

    python benchmarks/bench_bake.py fidelity [--size 1024] [--out DIR]
    python benchmarks/bench_bake.py time [--triangles 100000] [--size 1024] [--threads 1]
    python benchmarks/bench_bake.py memory [--triangles 1000000] [--size 1024]

fidelity: the shipped chair's texture (seed 0) on meshes the synthetic world did not make (a stool of
separate, open parts; a z-up STL of it scaled by 40) and on a world chair given as a raw mesh. Eight
views at 256 px (azimuths 0-315, elevation 20) of (a) the generator's field rendered on the prepared
shape, as ``infer generate`` renders it, and (b) the user's mesh with the baked texture, sampled
bilinearly; over the pixels both cover, 2 px away from either silhouette, the CIELAB colour
difference (CIE76) between them: median and 99th percentile; and over those of them where both
show the same point of the object (within 1 % of its size: not where the remeshed copy's leg stands
in front of the seat the user's mesh shows there). The row ``prepared`` bakes onto the
prepared shape itself (``--output-mesh prepared``, a fresh xatlas atlas): the bake's own error with
no mapping. ``--out`` also writes each mesh's renders side by side, and a zoom on the texture near a
seam of the atlas (``bake_*_seam.png``: the render, and the same square with the seams marked);
``bake_*.png`` has three rows: the user's mesh as given (grey), the field on the prepared copy, the
user's mesh with the baked texture.

time: a raw chair mesh subdivided to ``--triangles`` (default 100,000; ``--shape blob``: a bumpy blob,
curved everywhere, where xatlas has more to do), its texture baked at ``--size``
texels; the seconds of each part: the atlas (xatlas), the map (rasterizing the atlas and each
texel's closest point on the prepared surface), the colours (the field at those points) and the
writing; against the reference, the same size's bake onto the prepared shape as before (in the same
process). ``--threads`` sets torch's threads (the closest-point queries use one core).

memory: ``mesh2tex infer generate`` (one seed, one small view) on such a chair of ``--triangles``
(default 1,000,000) in a child process: its wall time and peak resident memory (ru_maxrss).
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
import trimesh

ROOT = Path(__file__).resolve().parents[1]
# fidelity: two renders show the same point of the object when their points are this close (bbox diagonals)
SAME_POINT = 0.01
sys.path.insert(0, str(ROOT / "tests"))  # the meshes a user brings, made apart from the world (tests/user_assets.py)


def chair_mesh(triangles: int = 0) -> trimesh.Trimesh:
    """Chair 0 of the synthetic world as a raw triangle mesh, faces split in four until it has about
    ``triangles`` (the last split only on as many faces as that needs)."""
    from mesh2tex.synthetic.shapes import generate_shape

    chair = generate_shape("chair", np.random.default_rng(0))
    mesh = trimesh.Trimesh(chair.vertices, chair.faces, process=False)
    while 4 * len(mesh.faces) <= triangles:
        mesh = mesh.subdivide()
    extra = (triangles - len(mesh.faces)) // 3  # splitting a face adds three
    if extra > 0:
        mesh = mesh.subdivide(face_index=np.arange(extra))
    return mesh


def blob_mesh(triangles: int) -> trimesh.Trimesh:
    """A bumpy closed blob of about ``triangles`` triangles, like a scan: curved everywhere, so that
    xatlas cuts many charts (a subdivided chair is mostly flat panels, the easy case)."""
    mesh = trimesh.creation.icosphere(subdivisions=1)
    while 4 * len(mesh.faces) <= triangles:
        mesh = mesh.subdivide()
    extra = (triangles - len(mesh.faces)) // 3
    if extra > 0:
        mesh = mesh.subdivide(face_index=np.arange(extra))
    v = mesh.vertices / np.linalg.norm(mesh.vertices, axis=1, keepdims=True)
    bumps = 1 + 0.15 * np.sin(5 * v[:, 0]) * np.cos(4 * v[:, 1]) + 0.05 * np.sin(11 * v[:, 2])
    return trimesh.Trimesh(v * bumps[:, None] * [1.0, 0.7, 0.5], mesh.faces, process=False)


def fidelity_meshes(folder: Path) -> dict[str, Path]:
    from user_assets import user_files

    files = user_files(folder)
    chair = folder / "world_chair.obj"
    chair_mesh().export(chair)
    return {"stool (PLY)": files["ply"], "stool z-up x40 (STL)": files["stl"], "world chair (OBJ)": chair}


def lab_difference(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(N, 3, H, W) images in [-1, 1] -> (N, H, W) CIE76 colour difference."""
    from kornia.color import rgb_to_lab

    return (rgb_to_lab(((a + 1) / 2).clamp(0, 1)) - rgb_to_lab(((b + 1) / 2).clamp(0, 1))).norm(dim=1)


def surface_positions(vertices, faces, mvp: torch.Tensor, size: int):
    """The surface point each pixel shows: (N, H, W, 3) (vertices' frame), mask (N, H, W), and the raster."""
    from mesh2tex.render import interpolate, rasterize, transform_points

    vertices = torch.as_tensor(np.asarray(vertices), dtype=torch.float32)
    faces = torch.as_tensor(np.asarray(faces), dtype=torch.int64)
    raster = rasterize(transform_points(vertices, mvp), faces, (size, size))
    return interpolate(vertices, raster, faces), raster.face_id >= 0, raster


def render_baked(
    vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, texture: np.ndarray, mvp: torch.Tensor, size: int
):
    """The baked mesh (vertices in the working frame) rendered with its texture: images (N, 3, H, W) in
    [-1, 1], mask (N, H, W), the surface point at each pixel (N, H, W, 3)."""
    from mesh2tex.render import interpolate
    from mesh2tex.render import sample_texture as sample

    positions, mask, raster = surface_positions(vertices, faces, mvp, size)
    texel_uv = interpolate(torch.from_numpy(uv).float(), raster, torch.from_numpy(np.asarray(faces, dtype=np.int64)))
    image = torch.from_numpy(texture).permute(2, 0, 1).float() / 127.5 - 1
    colours = sample(image, texel_uv)  # (N, H, W, 3)
    return torch.where(mask[..., None], colours, torch.ones_like(colours)).permute(0, 3, 1, 2), mask, positions


def plain_renders(vertices, faces, mvp: torch.Tensor, size: int) -> torch.Tensor:
    """The mesh as the user gave it, grey with flat shading from the camera's side: (N, 3, H, W) in [-1, 1]."""
    from mesh2tex.render import render_normals

    _, mask, raster = surface_positions(vertices, faces, mvp, size)
    normals = render_normals(
        torch.as_tensor(np.asarray(vertices), dtype=torch.float32),
        torch.as_tensor(np.asarray(faces), dtype=torch.int64),
        raster,
        smooth=False,
    )
    # towards the camera
    light = torch.nn.functional.normalize(torch.linalg.inv(mvp)[:, :3, 2], dim=-1)[:, None, None, :]
    grey = 0.35 + 0.55 * (normals * light).sum(-1).abs()
    return torch.where(mask, grey * 2 - 1, torch.ones_like(grey))[:, None].expand(-1, 3, -1, -1)


def seam_zoom(
    vertices, faces, uv, texture, mvp: torch.Tensor, size: int = 512, window: int = 64, scale: int = 4
) -> np.ndarray:
    """A zoom on the atlas's seams in one view: the ``window``-pixel square of a ``size`` render where
    the most seams cross the object (neighbouring pixels whose UVs jump: another chart), enlarged
    ``scale`` times, beside the same square with those seams marked red. (H, 2W, 3) uint8."""
    from mesh2tex.render import interpolate

    images, mask, _ = render_baked(vertices, faces, uv, texture, mvp, size)
    _, _, raster = surface_positions(vertices, faces, mvp, size)
    texel_uv = interpolate(torch.from_numpy(uv).float(), raster, torch.from_numpy(np.asarray(faces, dtype=np.int64)))[0]
    inside = eroded(mask)[0]
    jump = torch.zeros(size, size, dtype=torch.bool)
    jump[:, 1:] |= (texel_uv[:, 1:] - texel_uv[:, :-1]).norm(dim=-1) > 0.02
    jump[1:, :] |= (texel_uv[1:] - texel_uv[:-1]).norm(dim=-1) > 0.02
    seams = (jump & inside).float()
    counts = torch.nn.functional.avg_pool2d(seams[None, None], window, stride=8)[0, 0]
    row, col = divmod(int(counts.argmax()), counts.shape[1])
    top, left = row * 8, col * 8
    crop = (
        ((images[0].permute(1, 2, 0).numpy() + 1) * 127.5)
        .clip(0, 255)
        .astype(np.uint8)[top : top + window, left : left + window]
    )
    marked = crop.copy()
    marked[seams.numpy()[top : top + window, left : left + window] > 0] = (255, 0, 0)
    return np.concatenate([crop, marked], axis=1).repeat(scale, axis=0).repeat(scale, axis=1)


def eroded(mask: torch.Tensor, pixels: int = 2) -> torch.Tensor:
    """(N, H, W) bool -> the pixels at least ``pixels`` away from the mask's border."""
    kernel = 2 * pixels + 1
    return -torch.nn.functional.max_pool2d(-(mask.float()[:, None]), kernel, stride=1, padding=pixels)[:, 0] > 0.5


def fidelity(args) -> None:
    from PIL import Image

    from mesh2tex.models import load_generator
    from mesh2tex.nn.batch import collate_shapes
    from mesh2tex.nn.render_texture import render_field_views
    from mesh2tex.render import orbit_camera, turntable_angles
    from mesh2tex.render.bake import MeshBaker
    from mesh2tex.texturing import bake_texture, latent, load_shape

    model = load_generator("chair", torch.device("cpu"))
    generator, distance, fov = model.network, model.camera.distance, model.camera.fov
    mvp = orbit_camera(*turntable_angles(8, 20.0), distance=distance, fov=fov).mvp
    white = torch.ones(8, 3)
    folder = Path(tempfile.mkdtemp(prefix="bake-"))
    print(f"texture {args.size}^2, 8 views at 256 px, pixels 2 px inside both silhouettes; CIELAB difference (CIE76)")
    print(
        f"{'mesh':24s} {'target':9s} {'pixels of':11s} {'triangles':>9s} {'uv':>4s} {'pixels':>7s} {'median':>7s} "
        f"{'p99':>6s} {'max dist':>8s}"
    )
    for name, path in fidelity_meshes(folder).items():
        shape, target = load_shape(path, generator, model.face_count())
        batch = collate_shapes([shape])
        with torch.no_grad():
            texture = generator.synthesize(batch, latent(generator, 0, torch.device("cpu")), noise_mode="none")
            reference = render_field_views(generator, batch, None, mvp, (256, 256), white, texture=texture)

            baked = MeshBaker(target, batch.shape_vertices(0), batch.shape_triangles(0), args.size).bake(texture)
            user_images, user_mask, user_points = render_baked(
                target.surface_points(baked.vertices), baked.faces, baked.uv, baked.texture, mvp, 256
            )
            p_vertices, p_faces, p_uv, p_texture, _ = bake_texture(generator, texture, batch, args.size)
            prepared_images, prepared_mask, _ = render_baked(
                p_vertices.numpy(), p_faces.numpy(), p_uv.numpy(), p_texture, mvp, 256
            )
            reference_points, _, _ = surface_positions(batch.shape_vertices(0), batch.shape_triangles(0), mvp, 256)
        inside = eroded(reference.mask[:, 0] > 0.5)
        # pixels where the two meshes show the same point of the object (within 1 % of its size): not
        # where one shows a leg and the other the seat behind it, an edge of the remeshed copy
        same_point = (user_points - reference_points).norm(dim=-1) < SAME_POINT
        for label, images, mask, triangles, uv, far, where in (
            (
                "input",
                user_images,
                user_mask,
                len(baked.faces),
                baked.atlas.source,
                float(baked.surface_distance.max()),
                same_point,
            ),
            ("prepared", prepared_images, prepared_mask, len(p_faces), "new", 0.0, torch.ones_like(same_point)),
        ):
            both = inside & eroded(mask)
            for scope, pixels in (("silhouettes", both), ("same point", both & where)):
                delta = lab_difference(images, reference.images)[pixels]
                print(
                    f"{name:24s} {label:9s} {scope:11s} {triangles:9d} {uv:>4s} {int(pixels.sum()):7d} "
                    f"{float(delta.median()):7.2f} {float(torch.quantile(delta, 0.99)):6.2f} {far:8.4f}"
                )
        if args.out:
            out = Path(args.out)
            out.mkdir(parents=True, exist_ok=True)
            strip = lambda images: np.concatenate(
                [((i.permute(1, 2, 0).numpy() + 1) * 127.5).clip(0, 255).astype(np.uint8) for i in images[:4]], axis=1
            )
            slug = name.split(" ")[0] + ("_z_up" if "z-up" in name else "")
            before = plain_renders(target.surface_points(target.mesh.vertices), target.mesh.faces, mvp, 256)
            Image.fromarray(np.concatenate([strip(before), strip(reference.images), strip(user_images)], axis=0)).save(
                out / f"bake_{slug}.png"
            )
            Image.fromarray(baked.texture).save(out / f"bake_{slug}_texture.png")
            Image.fromarray(
                seam_zoom(target.surface_points(baked.vertices), baked.faces, baked.uv, baked.texture, mvp[:1])
            ).save(out / f"bake_{slug}_seam.png")


def timed_bake(triangles: int, size: int, shape: str = "chair") -> dict:
    """Seconds of each part of baking the shipped chair's texture onto a ``triangles``-triangle chair at ``size``."""
    from mesh2tex.geometry.closest import SurfaceIndex
    from mesh2tex.models import load_generator
    from mesh2tex.nn.batch import collate_shapes
    from mesh2tex.render.bake import MeshBaker, mesh_atlas
    from mesh2tex.texturing import bake_texture, latent, load_shape, write_baked_mesh

    folder = Path(tempfile.mkdtemp(prefix="bake-time-"))
    path = folder / "chair.ply"
    mesh = chair_mesh(triangles) if shape == "chair" else blob_mesh(triangles)
    mesh.export(path)
    model = load_generator("chair", torch.device("cpu"))
    generator = model.network
    start = time.perf_counter()
    shape, target = load_shape(path, generator, model.face_count())
    seconds = {"load and prepare": time.perf_counter() - start}
    batch = collate_shapes([shape])
    with torch.no_grad():
        texture = generator.synthesize(batch, latent(generator, 0, torch.device("cpu")), noise_mode="none")

        tick = time.perf_counter()
        mesh_atlas(target.mesh, "new")
        seconds["atlas (xatlas)"] = time.perf_counter() - tick
        tick = time.perf_counter()
        SurfaceIndex(batch.shape_vertices(0), batch.shape_triangles(0))
        seconds["surface index"] = time.perf_counter() - tick
        tick = time.perf_counter()
        baker = MeshBaker(target, batch.shape_vertices(0), batch.shape_triangles(0), size)
        seconds["map (atlas, raster, closest points)"] = time.perf_counter() - tick
        tick = time.perf_counter()
        baked = baker.bake(texture)
        seconds["colours"] = time.perf_counter() - tick
        tick = time.perf_counter()
        write_baked_mesh(folder / "out.glb", folder / "out.ply", baked, target.mesh)
        seconds["write GLB + PLY"] = time.perf_counter() - tick
        tick = time.perf_counter()
        bake_texture(generator, texture, batch, size)
        seconds["reference: bake onto the prepared shape"] = time.perf_counter() - tick
    seconds["user bake (map + colours + write)"] = (
        seconds["map (atlas, raster, closest points)"] + seconds["colours"] + seconds["write GLB + PLY"]
    )
    return {
        "triangles": len(mesh.faces),
        "texels": size * size,
        "coverage": float(baked.coverage.mean()),
        "seconds": seconds,
    }


def time_bake(args) -> None:
    torch.set_num_threads(args.threads)
    result = timed_bake(args.triangles, args.size, args.shape)
    print(
        f"{args.shape}: {result['triangles']} triangles, {args.size}^2 texels ({100 * result['coverage']:.0f} % "
        f"covered), {args.threads} torch thread(s)"
    )
    reference = result["seconds"]["reference: bake onto the prepared shape"]
    for part, value in result["seconds"].items():
        print(f"  {part:42s} {value:7.2f} s  ({value / reference:5.2f}x the reference)")


def memory(args) -> None:
    """``infer generate`` on a ``--triangles`` chair in a child process: its wall time and peak resident memory."""
    folder = Path(tempfile.mkdtemp(prefix="bake-memory-"))
    mesh = chair_mesh(args.triangles)
    mesh.export(folder / "chair.ply")
    start = time.perf_counter()
    subprocess.run(
        [
            sys.executable,
            "-m",
            "mesh2tex",
            "infer",
            "generate",
            "--checkpoint",
            "chair",
            "--mesh",
            str(folder / "chair.ply"),
            "--out",
            str(folder / "out"),
            "--seeds",
            "0",
            "--views",
            "1",
            "--resolution",
            "64",
            "--texture-size",
            str(args.size),
        ],
        check=True,
        capture_output=True,
    )
    seconds = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2**20  # kB -> GiB
    print(
        f"infer generate on {len(mesh.faces)} triangles at {args.size}^2 texels: {seconds:.0f} s, peak resident "
        f"memory {peak:.2f} GiB"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("what", choices=["fidelity", "time", "memory"])
    parser.add_argument("--size", type=int, default=1024)
    parser.add_argument("--triangles", type=int, default=None)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument(
        "--shape", choices=["chair", "blob"], default="chair", help="time: a subdivided world chair, or a bumpy blob"
    )
    parser.add_argument("--out", help="fidelity: folder for the side-by-side renders")
    args = parser.parse_args()
    if args.what == "fidelity":
        fidelity(args)
    elif args.what == "time":
        args.triangles = args.triangles or 100_000
        time_bake(args)
    else:
        args.triangles = args.triangles or 1_000_000
        memory(args)


if __name__ == "__main__":
    main()
