"""VGG19 style features: the activations after convolution layers 2, 4, 8, 12 and 16.

Counting the 16 convolution layers of VGG19 from 1, layers 2, 4, 8, 12, 16 are conv1_2, conv2_2,
conv3_4, conv4_4 and conv5_4; we return their ReLU outputs (relu1_2 ... relu5_4), the layers the
Mesh2Tex style losses use.

Weights. ImageNet weights are read from a local file, never downloaded:

1. the path given explicitly (``--vgg-weights PATH`` on the command line), else
2. the ``MESH2TEX_VGG_WEIGHTS`` environment variable, else
3. torchvision's cache file ``$TORCH_HOME/hub/checkpoints/vgg19-dcbb9e9d.pth`` (``$TORCH_HOME``
   defaults to ``$XDG_CACHE_HOME/torch``, then ``~/.cache/torch``, as in torch.hub).

The file is a plain state dict with torchvision's key names (``features.N.weight``/``bias``; the
classifier keys are ignored), read with ``torch.load(weights_only=True)``: torchvision itself is
not needed. With no file, a **random-weight VGG19** (fixed seed, Kaiming-normal filters) takes over
with a warning: random deep filters still measure texture statistics (colour, local frequency and
orientation), so Gram-matrix style losses keep working, but they are less perceptual than the
ImageNet features, and transfer results lose fine detail. An explicit path that does not hold VGG19
weights is a :class:`~mesh2tex.errors.InputError`, never a silent fallback.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import torch
import torch.nn as nn

from mesh2tex.checks import check_shape
from mesh2tex.errors import InputError

# torchvision's VGG19 "features" layout: channel counts, "M" for a 2x2 max pool.
VGG19_LAYOUT = [64, 64, "M", 128, 128, "M", 256, 256, 256, 256, "M", 512, 512, 512, 512, "M", 512, 512, 512, 512, "M"]
# 1-based indices of the convolution layers whose ReLU outputs are the style features.
STYLE_CONV_LAYERS = (2, 4, 8, 12, 16)
STYLE_LAYER_NAMES = ("relu1_2", "relu2_2", "relu3_4", "relu4_4", "relu5_4")
VGG19_FILE_NAME = "vgg19-dcbb9e9d.pth"
VGG19_URL = "https://download.pytorch.org/models/vgg19-dcbb9e9d.pth"
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
RANDOM_VGG_SEED = 0


def torch_hub_checkpoint_dir() -> Path:
    """``$TORCH_HOME/hub/checkpoints`` resolved the way torch.hub does (without importing torchvision)."""
    torch_home = os.environ.get("TORCH_HOME")
    if torch_home is None:
        torch_home = os.path.join(os.environ.get("XDG_CACHE_HOME", os.path.expanduser("~/.cache")), "torch")
    return Path(torch_home) / "hub" / "checkpoints"


def read_state_dict(path: Path, what: str) -> dict[str, torch.Tensor]:
    """A tensor state dict from a ``.pth`` (``torch.load(weights_only=True)``) or ``.safetensors`` file.

    Raises InputError naming ``path`` when the file cannot be read as a state dict of tensors.
    """
    if not path.is_file():
        raise InputError(f"{path}: {what} weight file not found")
    try:
        if path.suffix == ".safetensors":
            from safetensors.torch import load_file

            state = load_file(str(path))
        else:
            state = torch.load(str(path), map_location="cpu", weights_only=True)
    except Exception as error:  # torch.load raises many types for a file that is not a checkpoint
        raise InputError(f"{path}: not a readable {what} weight file ({error.__class__.__name__})") from None
    if isinstance(state, dict) and "state_dict" in state and isinstance(state["state_dict"], dict):
        state = state["state_dict"]
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise InputError(f"{path}: not a {what} state dict (expected a mapping of names to tensors)")
    return state


class VGG19Features(nn.Module):
    """VGG19 convolution trunk up to conv5_4, returning the five style activations.

    ``forward(images)``: images [B, 3, H, W] float in [-1, 1] (the network colour range); they are
    mapped to [0, 1] and ImageNet-normalised inside. Returns a list of 5 tensors
    [B, C_l, H / 2^l, W / 2^l] float (C = 64, 128, 256, 512, 512; l = 0..4), the ReLU outputs of
    convolution layers 2, 4, 8, 12 and 16. Any H, W >= 16 works.

    Attributes: ``pretrained`` (True for ImageNet weights), ``source`` (the weight file, or
    ``"random (seed 0)"``). Parameters are frozen; gradients flow to the input only.
    """

    def __init__(self):
        super().__init__()
        layers: list[nn.Module] = []
        in_channels = 3
        conv_count = 0
        for item in VGG19_LAYOUT:
            if conv_count == STYLE_CONV_LAYERS[-1] and item == "M":
                break  # nothing after conv5_4 is needed
            if item == "M":
                layers.append(nn.MaxPool2d(2, 2))
            else:
                layers.append(nn.Conv2d(in_channels, item, 3, padding=1))
                layers.append(nn.ReLU(inplace=False))
                in_channels = item
                conv_count += 1
        # Same indices as torchvision's vgg19().features, so its state dict keys load directly.
        self.features = nn.Sequential(*layers)
        conv_indices = [i for i, m in enumerate(self.features) if isinstance(m, nn.Conv2d)]
        self.output_indices = [conv_indices[k - 1] + 1 for k in STYLE_CONV_LAYERS]  # the ReLU after each
        self.register_buffer("mean", torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(IMAGENET_STD).view(1, 3, 1, 1), persistent=False)
        self.pretrained = False
        self.source = "uninitialised"

    def forward(self, images: torch.Tensor, depth: int = len(STYLE_CONV_LAYERS)) -> list[torch.Tensor]:
        """images (N, 3, H, W) float in [-1, 1] -> the first ``depth`` style activations (all five by default);
        the trunk stops after the last one asked for."""
        check_shape(images, "VGG19Features: images", (None, 3, None, None), dtype="float")
        x = ((images + 1.0) * 0.5 - self.mean) / self.std
        outputs = []
        last = self.output_indices[depth - 1]
        for index, module in enumerate(self.features):
            x = module(x)
            if index in self.output_indices:
                outputs.append(x)
            if index == last:
                break
        return outputs

    def init_random(self, seed: int = RANDOM_VGG_SEED) -> None:
        """Seeded Kaiming-normal filters and zero biases: activations keep their scale through depth."""
        generator = torch.Generator().manual_seed(seed)
        with torch.no_grad():
            for module in self.features:
                if isinstance(module, nn.Conv2d):
                    fan_in = module.in_channels * module.kernel_size[0] * module.kernel_size[1]
                    module.weight.copy_(torch.randn(module.weight.shape, generator=generator) * (2.0 / fan_in) ** 0.5)
                    module.bias.zero_()
        self.pretrained = False
        self.source = f"random (seed {seed})"

    def load_imagenet(self, path: str | os.PathLike) -> None:
        """Load torchvision-layout VGG19 weights from ``path``; InputError if it is not such a file."""
        path = Path(path)
        state = read_state_dict(path, "VGG19")
        own = self.features.state_dict()
        wanted = {f"features.{k}": v for k, v in own.items()}
        missing = [k for k in wanted if k not in state]
        if missing:
            raise InputError(
                f"{path}: not VGG19 weights: missing {len(missing)} key(s), e.g. '{missing[0]}' "
                f"(expected torchvision's vgg19 state dict, file {VGG19_FILE_NAME})"
            )
        for key, tensor in wanted.items():
            if tuple(state[key].shape) != tuple(tensor.shape):
                raise InputError(
                    f"{path}: not VGG19 weights: '{key}' has shape {tuple(state[key].shape)}, "
                    f"expected {tuple(tensor.shape)}"
                )
        self.features.load_state_dict({k: state[f"features.{k}"].float() for k in own})
        self.pretrained = True
        self.source = str(path)


def find_weight_file(
    path: str | os.PathLike | None, env_var: str, file_names: tuple[str, ...], what: str
) -> Path | None:
    """A local weight file: ``path``, else ``$env_var``, else the first of ``file_names`` present in
    torchvision's cache ``$TORCH_HOME/hub/checkpoints``; None if there is none.

    A path given explicitly (argument or environment variable) that does not exist is an InputError.
    """
    explicit = path if path is not None else os.environ.get(env_var) or None
    if explicit is not None:
        explicit = Path(explicit)
        if not explicit.is_file():
            raise InputError(f"{explicit}: {what} weight file not found")
        return explicit
    for name in file_names:
        candidate = torch_hub_checkpoint_dir() / name
        if candidate.is_file():
            return candidate
    return None


def find_vgg19_weights(path: str | os.PathLike | None = None) -> Path | None:
    """The VGG19 weight file to use: ``path``, else $MESH2TEX_VGG_WEIGHTS, else torchvision's cache file; None if none
    exists."""
    return find_weight_file(path, "MESH2TEX_VGG_WEIGHTS", (VGG19_FILE_NAME,), "VGG19")


def fallback_warning_text() -> str:
    """What the random-weight fallback means for quality, and how to get the real weights."""
    return (
        "no ImageNet VGG19 weights found (looked for $MESH2TEX_VGG_WEIGHTS and "
        f"{torch_hub_checkpoint_dir() / VGG19_FILE_NAME}); "
        f"using a random-weight VGG19 (seed {RANDOM_VGG_SEED}). Style losses still match colour and texture "
        "statistics, "
        "but less perceptually: expect blurrier, less faithful detail in transferred textures. To use the real "
        f"weights, download {VGG19_URL} into {torch_hub_checkpoint_dir()} or pass --vgg-weights PATH."
    )


_CACHE: dict[tuple[str, str], VGG19Features] = {}


def load_vgg19(
    weights: str | os.PathLike | None = None, device: str | torch.device = "cpu", warn: bool = True
) -> VGG19Features:
    """A frozen, eval-mode :class:`VGG19Features` on ``device``.

    ``weights``: a weight file path, or None to search ($MESH2TEX_VGG_WEIGHTS, then torchvision's
    cache). Without a file the seeded random-weight network is returned and (if ``warn``) a
    UserWarning explains the quality to expect. Models are cached per (file, device).
    """
    found = find_vgg19_weights(weights)
    if found is None and warn:  # every call that falls back says so, cached model or not
        warnings.warn(fallback_warning_text(), UserWarning, stacklevel=2)
    key = (str(found) if found is not None else "random", str(torch.device(device)))
    if key in _CACHE:
        return _CACHE[key]
    model = VGG19Features()
    if found is not None:
        model.load_imagenet(found)
    else:
        model.init_random()
    model = model.to(device).eval()
    for parameter in model.parameters():
        parameter.requires_grad_(False)
    _CACHE[key] = model
    return model
