"""Trained models: the checkpoint kinds and the shipped models (:mod:`.store`), and loading a trained
network of any kind (:mod:`.loading`). The shipped models themselves are the folders beside these
files (``chair/``, ``car/``: package data)."""

from .loading import TrainedAutomaton, TrainedGenerator, load_generator, load_nca, load_view_network, shape_hierarchy
from .store import (
    MODEL_FILES,
    export_inference_checkpoint,
    is_model_name,
    list_models,
    model_has,
    models_root,
    resolve_checkpoint,
    save_inference_checkpoint,
)

__all__ = [
    "MODEL_FILES",
    "TrainedAutomaton",
    "TrainedGenerator",
    "export_inference_checkpoint",
    "is_model_name",
    "list_models",
    "load_generator",
    "load_nca",
    "load_view_network",
    "model_has",
    "models_root",
    "resolve_checkpoint",
    "save_inference_checkpoint",
    "shape_hierarchy",
]
