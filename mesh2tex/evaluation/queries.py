"""One query of a transfer protocol: what the transfer is given (:class:`QuerySetup`: the photo, the
shape, the pose, the view) and how every method on it is judged (:class:`QueryJudge`: the ground truth,
one render function, one score). ``cfg`` is the protocol's config
(:class:`mesh2tex.evaluation.protocol_config.ProtocolConfig`; ``unseen_views``, ``lighting``, ``lowpass_sigma``,
``seed``, ``transfer.pose_search``) and ``base`` the transfer config it makes."""

from __future__ import annotations

from mesh2tex.errors import InputError
from mesh2tex.evaluation import (
    ComparisonRender,
    ScoreSettings,
    common_mask,
    flat_surface,
    other_views,
    photo_mean_colour,
    render_for_comparison,
    score_views,
    seen_and_unseen,
)
from mesh2tex.evaluation.world import World, load_query_truth, load_shape_truth, reference_renders
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.geometry.symmetry import azimuth_symmetries
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.nn.pose import azimuth_error, symmetric_azimuth_error
from mesh2tex.transfer import estimate_pose, load_photo, predict_noc, view_at_pose


class QuerySetup:
    """One query of a transfer protocol: its photo (and NOC), the shape it textures, the pose the
    transfer uses (the truth with ``known_pose``, else the pose network's) and the view there."""

    def __init__(
        self,
        protocol: str,
        query,
        shapes: dict,
        targets: dict,
        base,
        cfg,
        pose_checkpoint,
        noc_checkpoint,
        distance: float,
        fov: float,
        device,
    ):
        self.protocol, self.query, self.exact = protocol, query, protocol in ("known_pose", "unknown_pose")
        self.photo, _ = load_photo(query.image, query.mask, base)
        self.photo_noc = predict_noc(noc_checkpoint, self.photo, device) if noc_checkpoint else None
        self.target = query.shape if self.exact else targets[query.shape]
        self.shape = shapes[self.target]
        self.batch = collate_shapes([self.shape])
        network_pose = None
        if protocol == "known_pose":
            self.azimuth, self.elevation, self.distance, self.fov = (
                query.azimuth,
                query.elevation,
                query.distance,
                query.fov,
            )
        else:
            estimate = estimate_pose(pose_checkpoint, self.shape, self.photo, distance, fov, base, device)
            self.azimuth, self.elevation, network_pose = estimate.azimuth, estimate.elevation, estimate.network
            self.distance, self.fov = distance, fov
        self.view = view_at_pose(self.shape, self.azimuth, self.elevation, self.distance, self.fov, base)
        self.record = {
            "query": query.name,
            "shape": self.target,
            "azimuth": round(self.azimuth, 3),
            "elevation": round(self.elevation, 3),
            "true_azimuth": query.azimuth,
            "true_elevation": query.elevation,
            "azimuth_error": round(float(azimuth_error(self.azimuth, query.azimuth)), 3),
            "elevation_error": round(abs(self.elevation - query.elevation), 3),
        }
        if network_pose is not None and cfg.transfer.pose_search:
            self.record["network_azimuth_error"] = round(float(azimuth_error(network_pose[0], query.azimuth)), 3)

    def judge_pose(self, turns: list[float]) -> None:
        """Adds to the record the found pose's azimuth error up to the photographed shape's own symmetries
        (``turns``, :func:`azimuth_symmetries`: a backless bench found half a turn off is not wrong) and how
        many turns those are. Nothing with ``known_pose``."""
        if self.protocol == "known_pose":
            return
        self.record["symmetries"] = len(turns)
        error = symmetric_azimuth_error(self.azimuth, self.query.azimuth, turns)
        self.record["symmetric_azimuth_error"] = round(error, 3)


class QueryJudge:
    """The ground truth of one query and one render function and one score for every method: the photo's
    view and ``cfg.unseen_views`` others, against the query photo and the world's own renders."""

    def __init__(self, protocol: str, world: World, query, target: str, shape: PreparedShape, cfg):
        self.exact, self.cfg = protocol in ("known_pose", "unknown_pose"), cfg
        self.settings = ScoreSettings(lowpass_sigma=cfg.lowpass_sigma, seed=cfg.seed)
        offsets = [360.0 * k / (cfg.unseen_views + 1) for k in range(1, cfg.unseen_views + 1)]
        try:
            self.truth = load_query_truth(world.root, world.index, query.record)
            target_truth = self.truth.truth if self.exact else load_shape_truth(world.root, world.index, target)
        except ValueError as error:
            raise InputError(str(error)) from None
        self.views = [self.truth.view] + other_views(self.truth.view, offsets)
        # the turns of the photographed shape that look the same: what a found pose is judged up to
        self.turns = [0.0] if protocol == "known_pose" else azimuth_symmetries(self.truth.truth.shape.vertices)
        self.reference = reference_renders(self.truth, self.views, cfg.lighting)
        self.oracle = self.render(self.truth.truth.oracle if self.exact else self.truth.truth.material_on(target_truth))
        self.vertices, self.triangles = shape.vertices[0], shape.triangles(0)
        self.flat = self.render(
            flat_surface(
                self.vertices, self.triangles, photo_mean_colour(self.truth.photo[0], self.truth.photo_mask[0])
            )
        )
        # Exact geometry: every method on the pixels both the world's shape and the prepared one cover, with
        # the world's part labels. Another shape: each image on its own object pixels, parts by label.
        self.mask = (
            common_mask(self.reference.mask, self.flat.mask)
            if self.exact
            else common_mask(self.flat.mask, self.oracle.mask)
        )

    def render(self, surface):
        return render_for_comparison(surface, self.views, self.truth.render_settings(self.cfg.lighting))

    def score(self, rendered) -> dict:
        reference = self.reference
        if self.exact:
            scores = score_views(rendered, reference.rgb, reference.parts, self.mask, self.settings)
        else:
            scores = score_views(
                ComparisonRender(rendered.rgb, self.mask, self.oracle.parts),
                reference.rgb,
                reference.parts,
                self.mask,
                self.settings,
                reference_mask=reference.mask,
            )
        return {k: round(v, 5) for k, v in seen_and_unseen(scores).items()}
