"""mesh2tex: learn to texture 3D meshes from photographs (Mesh2Tex), in pure PyTorch.

Library layout (one home per concept):
    mesh2tex.geometry   meshes, cleaning, quad hierarchies, neighbourhoods, features, prepared-shape records
    mesh2tex.render     cameras, rasterizer, interpolation, shading, UV-space rasterization, baking
    mesh2tex.nn         face convolutions, generator, neural field, discriminators, pose and NOC nets, VGG
    mesh2tex.losses     GAN losses and regularisers, style losses
    mesh2tex.metrics    KID/FID, sliced Wasserstein, PSNR/SSIM, histogram distances
    mesh2tex.io         atomic writes, checkpoints (safetensors + JSON), images, textured assets
    mesh2tex.synthetic  the procedural synthetic world (shapes, materials)
The pipeline stages that read and write files live in the packages data_prep/, train/ and infer/.
"""

__version__ = "0.1.0"
