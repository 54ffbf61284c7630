"""The options of ``mesh2tex infer generate|transfer|nca|synthesize`` and ``demo``, built without
importing torch (``--help`` stays fast; the defaults shown are read from the configs' source, see
:mod:`mesh2tex.options`); each command's ``run()`` and ``build_config()`` are in its own module."""

from __future__ import annotations

import argparse

from mesh2tex.options import (
    DEVICES,
    ConfigOptions,
    add_device,
    add_mesh_output,
    add_out,
    add_overwrite,
    add_texture_format,
    static_value,
)


def generate(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--checkpoint",
        required=True,
        help="GAN checkpoint (RUN/checkpoint.safetensors) or a shipped model's name (chair, car)",
    )
    parser.add_argument(
        "--mesh", required=True, help="a prepared shape (.npz) or a mesh file (.obj .ply .off .stl .glb)"
    )
    add_out(parser, "output folder")
    config = ConfigOptions(parser, "mesh2tex.infer.generate:GenerateConfig", what="the generate config")
    config.add("--seeds", help="latent seeds, one texture each: a list and ranges, e.g. 0,2,5-9")
    config.add("--views", type=int, help="orbit views per seed")
    config.add("--resolution", type=int, help="render resolution")
    config.add("--texture-size", type=int, help="baked UV texture size")
    add_texture_format(parser, config)
    config.add("--elevation", type=float, help="elevation of the orbit views, degrees")
    config.add("--truncation", type=float, help="truncation psi of the latent (1: none)")
    config.add(
        "--faces",
        type=int,
        help="finest quad count when preparing a raw mesh (0: the hierarchy the model was trained on)",
    )
    add_mesh_output(parser)
    config.add("--device", choices=DEVICES, help="where to run")
    parser.add_argument("--overwrite", action="store_true", help="replace files already in --out")


def transfer(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--checkpoint",
        required=True,
        help="GAN checkpoint (RUN/checkpoint.safetensors from 'train gan'), or a shipped "
        "model's name (chair, car), which also supplies the pose, NOC and mask networks unless given",
    )
    parser.add_argument("--mesh", required=True, help="the mesh to texture: a prepared shape (.npz) or a mesh file")
    parser.add_argument("--image", required=True, help="the query photo")
    parser.add_argument(
        "--mask",
        help="object mask of the photo (white = object); default: alpha channel, else an estimate "
        "(the mask network with GrabCut edges, or GrabCut alone without one)",
    )
    parser.add_argument("--pose", default="auto", help="'auto' (pose network) or AZIMUTH,ELEVATION in degrees")
    parser.add_argument("--pose-checkpoint", help="pose network checkpoint (from 'train pose'), for --pose auto")
    parser.add_argument("--noc-checkpoint", help="NOC network checkpoint (from 'train noc'), for NOC-guided patches")
    parser.add_argument(
        "--mask-checkpoint",
        help="mask network checkpoint (from 'train mask'), for a photo without a mask or alpha "
        "channel; without one (and no shipped model's), the mask is estimated by GrabCut alone",
    )
    add_out(parser, "output folder")
    config = ConfigOptions(parser, "mesh2tex.transfer.config:TransferConfig", what="the transfer config")
    config.add("--resolution", type=int, help="side of the photo crop and the renders")
    config.add("--latent-iters", type=int, help="stage 1 iterations")
    config.add("--refine-iters", type=int, help="stage 2 iterations")
    config.add("--texture-size", type=int, help="side of the UV texture baked into textured.glb")
    add_texture_format(parser, config)
    parser.add_argument("--no-noc", action="store_true", help="ablation: patch pairs without NOC guidance")
    parser.add_argument("--no-patches", action="store_true", help="ablation: global style loss only")
    parser.add_argument("--no-refine", action="store_true", help="ablation: optimise the latent only")
    parser.add_argument(
        "--no-pose-search",
        action="store_true",
        help="--pose auto takes the pose network's bin centres as they are (the paper), without the silhouette search",
    )
    parser.add_argument(
        "--automaton",
        action="store_true",
        help="fit a mesh automaton to the photo with the same losses instead of the GAN's texture (unlit, no GAN "
        "prior)",
    )
    config.add("--automaton-iters", type=int, key="automaton.iters", help="with --automaton: its iterations")
    config.add(
        "--faces",
        type=int,
        help="finest quad count when preparing a raw mesh (0: the hierarchy the model was trained on)",
    )
    add_mesh_output(parser)
    config.add(
        "--vgg-weights",
        help="VGG19 ImageNet weights (torchvision's vgg19-dcbb9e9d.pth; default: torch's cache, else random weights)",
    )
    config.add("--device", choices=DEVICES, help="where to run")
    config.add("--seed", type=int, help="random seed")
    parser.add_argument("--overwrite", action="store_true", help="replace the results already in --out")


def nca(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--checkpoint", required=True, help="a 'train nca' model (RUN/model.safetensors) or checkpoint")
    parser.add_argument("--mesh", default="sphere", help="sphere, sphere:N, a prepared shape (.npz) or a mesh file")
    add_out(parser, "output folder")
    config = ConfigOptions(parser, "mesh2tex.infer.nca:InferNCAConfig", what="the infer nca config")
    config.add("--steps", type=int, help="automaton steps from the seed")
    parser.add_argument("--graft", help="a second model of the same lineage, grown where --graft-mask is 1")
    parser.add_argument(
        "--graft-mask",
        default="smoothstep(-0.15, 0.15, x)",
        help="where the --graft model grows: an expression in x, y, z (the mesh in the unit ball) or a per-vertex "
        ".npy/.txt file",
    )
    parser.add_argument(
        "--regrow", help="after growth, zero the cells where this expression (or file) is above 0.5 and grow them back"
    )
    config.add("--angle", type=float, help="texture orientation: degrees about each vertex normal")
    config.add(
        "--subdivide",
        help="split faces into four N times (0: the mesh as it is); auto: the count whose edges come nearest the "
        "training mesh's",
    )
    config.add("--views", type=int, help="renders around the mesh")
    config.add("--resolution", type=int, help="render resolution")
    config.add("--texture-size", type=int, help="baked texture size")
    add_texture_format(parser, config)
    config.add("--frames", type=int, help="frames of growth.gif (0: no GIF)")
    config.add("--seed", type=int, help="seed of the asynchronous updates")
    add_mesh_output(parser)
    config.add("--vgg-weights", help="VGG19 weights for the report's style loss")
    config.add("--device", choices=DEVICES, help="where to run")
    parser.add_argument("--overwrite", action="store_true", help="replace outputs already in --out")


def synthesize(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--exemplar", required=True, help="the exemplar image whose structure the texture takes (its centred square)"
    )
    parser.add_argument("--mesh", required=True, help="the mesh to texture: a mesh file (.obj .ply .off .stl .glb)")
    add_out(parser, "output folder")
    config = ConfigOptions(
        parser, "mesh2tex.infer.synthesize:InferSynthesizeConfig", what="the infer synthesize config"
    )
    config.add(
        "--texture-size", type=int, key="synthesis.texture_size", help="side of the UV texture optimised and written"
    )
    config.add("--iters", type=int, key="synthesis.iters", help="optimisation steps")
    config.add(
        "--direction-field",
        key="synthesis.direction_field",
        choices=static_value("mesh2tex.texel_synthesis:DIRECTIONS"),
        help="up: every view (or chart) upright, so stripes keep one direction relative to --direction-axis; "
        "smooth (--method surface or patches): the smoothest field that follows that axis where the surface is "
        "steep, folded over the edges of faces that look along it (a chair's seat, a car's roof) where up jumps; "
        "none: rolled at random, each region of the surface takes an orientation of its own",
    )
    config.add(
        "--direction-axis",
        key="synthesis.direction_axis",
        choices=static_value("mesh2tex.geometry.direction_field:AXES"),
        help="the axis the direction field follows (--method surface or patches for x and z): y, the mesh's up, "
        "or x or z of its working frame (after --up: z is the file's z for y-up files, its -y for z-up ones)",
    )
    config.add(
        "--method",
        key="synthesis.method",
        choices=static_value("mesh2tex.texel_synthesis:METHODS"),
        help="how the loss sees the surface: renders (random rendered views), surface (geodesic charts walked "
        "on the surface along the direction field: no foreshortening, hidden parts included) or patches (with "
        "--loss patch: the loss's patches walked on the surface at each octave's scale); default: patches with "
        "--loss patch, renders with the others",
    )
    config.add(
        "--loss",
        key="synthesis.loss",
        choices=static_value("mesh2tex.texel_synthesis:SYNTHESIS_LOSSES"),
        help="structure loss: patch (sliced Wasserstein on raw multi-scale patches, no network; draws stripes and "
        "corners), ps (oriented-band statistics, no network), sw (sliced Wasserstein on random VGG features), ot "
        "(relaxed optimal transport on them)",
    )
    config.add(
        "--resolution",
        type=int,
        key="synthesis.resolution",
        help="render resolution; an exemplar pixel shows at one pixel of a view of the whole mesh",
    )
    config.add("--views", type=int, help="renders written (view_K.png) and judged")
    add_texture_format(parser, config)
    config.add("--seed", type=int, key="synthesis.seed", help="seed of the views and the initial texture")
    add_mesh_output(parser)
    config.add("--vgg-weights", help="VGG19 weights for the sw and ot losses")
    config.add("--device", choices=DEVICES, help="where to run")
    add_overwrite(parser, "replace outputs already in --out")


def demo(parser: argparse.ArgumentParser) -> None:
    add_out(parser, "output folder", required=False, default="demo_out")
    config = ConfigOptions(parser, "mesh2tex.infer.demo:DemoConfig", what="the demo config")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="a smoke-test budget (a minute or two): every stage runs, nothing learns much",
    )
    config.add("--seed", type=int, help="master seed")
    add_texture_format(parser, config, key="transfer.texture_format")
    add_device(parser, help="where every stage runs")
    add_overwrite(
        parser, help="start again: remove what an earlier demo wrote in --out (without it, the demo resumes there)"
    )
