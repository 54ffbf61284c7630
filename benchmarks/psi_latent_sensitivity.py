"""How much psi's colours depend on the latent, against how much they depend on its geometry input.

    python benchmarks/psi_latent_sensitivity.py --checkpoint CKPT --shapes DIR [--latents 8] [--resolution 64]

For every prepared shape in DIR (up to 4) and pairs of random latents, at 4 views: the mean absolute
change of psi's colours at the covered pixels when the latent is swapped (the texture should follow
the latent), of the proxy (per-face) colours under the same swap, and, when the generator gives psi
a projection of the geometry features E_0 (``field_geometry_channels`` > 0), the change when that
projection is frozen to its mean over the faces (how much psi leans on the latent-free input).
Colours in [-1, 1].
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.geometry.prepared import PreparedShape  # noqa: E402
from mesh2tex.models import load_generator  # noqa: E402
from mesh2tex.nn.batch import collate_shapes  # noqa: E402
from mesh2tex.nn.generator import FaceTexture  # noqa: E402
from mesh2tex.nn.render_texture import rasterize_batch  # noqa: E402
from mesh2tex.render import orbit_camera  # noqa: E402


@torch.no_grad()
def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--checkpoint", required=True)
    parser.add_argument("--shapes", required=True)
    parser.add_argument("--latents", type=int, default=8)
    parser.add_argument("--resolution", type=int, default=64)
    args = parser.parse_args()
    torch.set_num_threads(1)
    model = load_generator(args.checkpoint, torch.device("cpu"))
    generator, distance, fov = model.network, model.camera.distance, model.camera.fov
    paths = sorted(Path(args.shapes).glob("*.npz"))[:4]
    latent_swap, proxy_swap, frozen = [], [], []
    z = torch.randn(args.latents, generator.cfg.z_dim, generator=torch.Generator().manual_seed(0))
    for path in paths:
        batch = collate_shapes([PreparedShape.load(path)])
        mvp = orbit_camera(
            torch.tensor([30.0, 120.0, 210.0, 300.0]), torch.full((4,), 20.0), distance=distance, fov=fov
        ).mvp
        samples = rasterize_batch(batch, mvp, (args.resolution, args.resolution))
        covered = samples.mask.reshape(-1)
        triangle_id, bary = samples.triangle_id.reshape(-1)[covered], samples.bary.reshape(-1, 3)[covered]
        encoded = generator.encoder(batch)
        colours, faces = [], []
        for k in range(args.latents):
            texture = generator.synthesize(batch, generator.mapping(z[k : k + 1]), encoded=encoded, noise_mode="none")
            colours.append(texture.colours(triangle_id, bary))
            faces.append(texture.face_rgb[triangle_id // 2])
            if generator.field_geometry is not None:
                width = generator.cfg.field_geometry_channels
                geometry = texture.field_features[:, -width:]
                flat = torch.cat(
                    [texture.field_features[:, :-width], geometry.mean(0, keepdim=True).expand_as(geometry)], dim=1
                )
                still = FaceTexture(flat, texture.face_rgb).bound(generator, batch).colours(triangle_id, bary)
                frozen.append((still - colours[-1]).abs().mean())
        for i in range(args.latents):
            for j in range(i + 1, args.latents):
                latent_swap.append((colours[i] - colours[j]).abs().mean())
                proxy_swap.append((faces[i] - faces[j]).abs().mean())
    print(f"{args.checkpoint} (iteration {model.iteration}), {len(paths)} shapes, {args.latents} latents")
    print(f"psi colour change under a latent swap:   {torch.stack(latent_swap).mean():.4f}")
    print(f"proxy colour change under a latent swap: {torch.stack(proxy_swap).mean():.4f}")
    if frozen:
        print(f"psi colour change with the geometry projection frozen to its mean: {torch.stack(frozen).mean():.4f}")
    else:
        print("psi sees F_c alone (field_geometry_channels 0): no latent-free input to freeze")


if __name__ == "__main__":
    main()
