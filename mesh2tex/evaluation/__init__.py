"""Quality tables on equal footing: candidates as textured surfaces, one render function, fair scores.

``surfaces``: the candidates (UV texture, flat colour, procedural material, a generator's field, photo
back-projection); ``compare``: :func:`render_for_comparison`, the views a photo does not show, and
:func:`score_views`; ``world``: the synthetic world's queries and their ground truth (the oracle);
``paired``: methods compared query by query (wins, Wilcoxon tests, the oracle check); ``report``:
the markdown tables of ``mesh2tex evaluate --protocols``.
The metrics themselves live in :mod:`mesh2tex.metrics.appearance`.
"""

from mesh2tex.evaluation.compare import (
    ALIGNED_ONLY,
    METRIC_TITLES,
    METRICS,
    ComparisonRender,
    ScoreSettings,
    common_mask,
    images_to_unit,
    metric_direction,
    other_views,
    render_for_comparison,
    score_views,
    seen_and_unseen,
)
from mesh2tex.evaluation.surfaces import (
    Surface,
    SurfacePoints,
    backproject_photo,
    backprojected_surface,
    flat_surface,
    generator_surface,
    material_surface,
    photo_mean_colour,
    textured_surface,
    vertex_colour_surface,
    with_parts,
)
from mesh2tex.render.settings import LIGHTING

__all__ = [
    "ALIGNED_ONLY",
    "LIGHTING",
    "METRICS",
    "METRIC_TITLES",
    "ComparisonRender",
    "ScoreSettings",
    "Surface",
    "SurfacePoints",
    "backproject_photo",
    "backprojected_surface",
    "common_mask",
    "flat_surface",
    "generator_surface",
    "images_to_unit",
    "material_surface",
    "metric_direction",
    "other_views",
    "photo_mean_colour",
    "render_for_comparison",
    "score_views",
    "seen_and_unseen",
    "textured_surface",
    "vertex_colour_surface",
    "with_parts",
]
