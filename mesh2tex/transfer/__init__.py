"""Texture transfer (Mesh2Tex section 3.3): texture a mesh after one photo of a similar object.

``config``: :class:`TransferConfig` and its checks; ``photo``: the photo cropped around its object
(:func:`load_photo`; :func:`photo_masks` and :func:`frame_photo` when the mask is estimated) and the mesh seen at a
pose, cropped alike (:func:`view_at_pose`, :func:`normals_at_pose`); ``pose``: the pose network's beliefs and the
silhouette search with its half-turn check (:func:`estimate_pose`, :func:`crease_agreement`; :func:`pick_by_outline`
picks among mask estimates; :func:`locate_object` finds the mask and the pose together), the NOC network
(:func:`predict_noc`); ``optimise``: :func:`transfer_texture` and the losses against the photo (:class:`PhotoLoss`);
``automaton``: a mesh automaton fitted to the photo with those losses, no GAN (:func:`fit_automaton`). The command
``mesh2tex infer transfer`` (``infer/transfer.py``) reads the files and writes the results.
"""

from mesh2tex.transfer.automaton import AutomatonFit, AutomatonFitConfig, fit_automaton
from mesh2tex.transfer.config import ABLATIONS, TransferConfig, check_style_sizes
from mesh2tex.transfer.optimise import PhotoLoss, TransferResult, transfer_texture
from mesh2tex.transfer.photo import (
    FramedView,
    MaskedPhoto,
    Photo,
    frame_photo,
    load_photo,
    normals_at_pose,
    photo_candidates,
    photo_masks,
    view_at_pose,
)
from mesh2tex.transfer.pose import (
    Located,
    PoseBeliefs,
    PoseEstimate,
    crease_agreement,
    estimate_pose,
    locate_object,
    pick_by_outline,
    pose_network_beliefs,
    predict_noc,
    predict_pose,
    search_pose,
    silhouette_iou,
)

__all__ = [
    "ABLATIONS",
    "AutomatonFit",
    "AutomatonFitConfig",
    "FramedView",
    "Located",
    "MaskedPhoto",
    "Photo",
    "PhotoLoss",
    "PoseBeliefs",
    "PoseEstimate",
    "TransferConfig",
    "TransferResult",
    "check_style_sizes",
    "crease_agreement",
    "estimate_pose",
    "fit_automaton",
    "frame_photo",
    "load_photo",
    "locate_object",
    "normals_at_pose",
    "photo_candidates",
    "photo_masks",
    "pick_by_outline",
    "pose_network_beliefs",
    "predict_noc",
    "predict_pose",
    "search_pose",
    "silhouette_iou",
    "transfer_texture",
    "view_at_pose",
]
