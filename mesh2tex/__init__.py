"""mesh2tex: learn to texture 3D meshes from photographs (Mesh2Tex), in pure PyTorch.

Library layout (one home per concept):
    mesh2tex.geometry   meshes, cleaning, quad hierarchies, neighbourhoods, features, prepared-shape records
    mesh2tex.render     cameras, rasterizer, interpolation, shading, UV-space rasterization, baking
    mesh2tex.nn         face convolutions, generator, neural field, discriminators, pose and NOC nets, VGG
    mesh2tex.losses     GAN losses and regularisers, style losses
    mesh2tex.metrics    KID/FID, sliced Wasserstein, PSNR/SSIM, histogram distances, set and pair evaluations
    mesh2tex.evaluation quality tables on equal footing: surfaces, one render function, the world's ground truth,
                        paired statistics, the protocols' report
    mesh2tex.transfer   texture transfer: the photo, the pose search, the optimisation
    mesh2tex.io         atomic writes, checkpoints of every kind (safetensors + JSON), images, textured assets
    mesh2tex.synthetic  the procedural synthetic world (shapes, materials)
    mesh2tex.texturing    a generator's texture on a shape: latents, vertex colours, UV baking
    mesh2tex.runtime    devices, processes, seeding, RNG state, EMA
    mesh2tex.photos     object masks (GrabCut) and square crops of photos
The pipeline stages that read and write files live in the folders data_prep/, train/ and infer/ of the
source tree, imported as ``mesh2tex.data_prep``, ``mesh2tex.train`` and ``mesh2tex.infer``; they import the
library and never one another (docs/architecture.md).
"""

from pathlib import Path as _Path

__version__ = "0.1.0"

# An installed wheel holds the stage folders inside this package (pyproject.toml maps them there, so it
# claims no generic top-level name). In a source tree they sit beside it: let the package find them there.
_SOURCE_TREE = _Path(__file__).resolve().parent.parent
if not (_Path(__file__).parent / "infer").is_dir() and (_SOURCE_TREE / "infer" / "__init__.py").is_file():
    __path__.append(str(_SOURCE_TREE))
