"""The single-photo transfer without a GAN: a mesh automaton (:class:`mesh2tex.nn.nca.MeshNCA`)
grown on the mesh and fitted to the photo with the transfer's losses.

Where :func:`mesh2tex.transfer.transfer_texture` searches a trained generator's texture space, this
fits a fresh automaton, cells on the finest vertices of the prepared mesh, so that its growth,
rendered at the photo's pose and cropped alike, matches the photo: the global style loss, the
patch style loss over NOC-guided patch pairs and the low-pass colour loss of :class:`PhotoLoss`,
with the settings of :class:`~mesh2tex.transfer.TransferConfig`. Every iteration grows the
automaton from its seed for a random number of steps and back-propagates through the growth,
as ``train nca`` does; the overflow penalty keeps states and colours in range. Since the rule is
local and the same everywhere, the sides the photo does not show grow the texture the rule makes
on the sides it shows.

The renders are unlit: the automaton takes the photo's shading into its colours, as photo
back-projection does.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import torch

from mesh2tex.errors import InputError
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.nn.cell_graph import CellGraph, build_cell_graph
from mesh2tex.nn.nca import MeshNCA, overflow_penalty
from mesh2tex.nn.render_texture import render_states
from mesh2tex.progress import progress_bar
from mesh2tex.render import crop_square
from mesh2tex.transfer.config import AutomatonFitConfig, TransferConfig
from mesh2tex.transfer.optimise import PhotoLoss
from mesh2tex.transfer.photo import FramedView, Photo, check_query


@dataclass
class AutomatonFit:
    model: MeshNCA  # the fitted automaton
    graph: CellGraph  # its cells: the finest vertices of the shape
    state: torch.Tensor  # (1, V, C) the grown state of the result
    colours: torch.Tensor  # (V, 3) the result's colour at each cell, in [0, 1]
    render: torch.Tensor  # (1, 3, R, R) the result at the pose, cropped, in [-1, 1]
    losses: list[float]  # one per iteration
    seconds: float


def fit_automaton(
    shape: PreparedShape,
    photo: Photo,
    view: FramedView,
    photo_noc: torch.Tensor | None,
    vgg,
    cfg: TransferConfig,
    fit: AutomatonFitConfig,
    device: torch.device,
    show_progress: bool = True,
) -> AutomatonFit:
    """Fit an automaton on ``shape``'s finest level to ``photo`` seen at ``view`` (see the module docstring).

    ``photo_noc`` (R,R,3) is needed when ``cfg.use_noc`` and ``cfg.use_patches``; the patch loss
    replaces the global one when ``cfg.use_patches`` (the transfer's stage 2), and ``cfg.seed``
    seeds the growth and the patch pairs. photo: image (1, 3, R, R), mask (1, 1, R, R); view: noc (R, R, 3),
    mask (1, 1, R, R).
    """
    check_query(photo, view, photo_noc, "fit_automaton")
    start = time.perf_counter()
    loss_of = PhotoLoss(photo, view, photo_noc, vgg, cfg, device)
    graph = build_cell_graph(shape.vertices[0], shape.quads[0], fit.nca.neighbourhood).to(device)
    # the update rule's initial weights, seeded, leaving the caller's generator alone
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(cfg.seed)
        model = MeshNCA(fit.nca).to(device)
    growth = torch.Generator(device=device).manual_seed(cfg.seed)
    mvp = view.mvp.to(device)

    def grown(steps: int) -> torch.Tensor:
        return model.rollout(
            model.seed_state(1, graph.num_cells, device, generator=growth), graph, steps, generator=growth
        )

    def render(state: torch.Tensor) -> torch.Tensor:
        full = render_states(model, state, graph, mvp, view.render_size, background=0.0).images
        return crop_square(full, view.box, cfg.resolution)

    optimiser = torch.optim.Adam(model.parameters(), lr=fit.lr)
    losses: list[float] = []
    iterator = progress_bar(range(fit.iters), desc="automaton") if show_progress else range(fit.iters)
    for _ in iterator:
        steps = int(torch.randint(fit.steps_min, fit.steps_max + 1, (1,), generator=growth, device=device))
        state = grown(steps)
        total, _ = loss_of(render(state), use_global=not cfg.use_patches)
        total = total + fit.overflow_weight * overflow_penalty(state, model.vertex_colours(state))
        if not torch.isfinite(total):
            raise InputError(f"automaton fit: the loss became {float(total)}; lower the learning rate (lr)")
        optimiser.zero_grad(set_to_none=True)
        total.backward()
        with torch.no_grad():  # per-parameter gradient normalisation, as train nca
            for p in model.parameters():
                if p.grad is not None:
                    p.grad /= p.grad.norm() + 1e-8
        optimiser.step()
        losses.append(round(float(total.detach()), 6))
        if show_progress:
            iterator.set_postfix(loss=f"{losses[-1]:.4f}")
    with torch.no_grad():
        state = grown(fit.final_steps)
        image = render(state)
        colours = ((model.vertex_colours(state)[0] + 1) / 2).clamp(0, 1)
    return AutomatonFit(model, graph, state, colours, image.cpu(), losses, round(time.perf_counter() - start, 2))
