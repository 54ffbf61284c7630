"""The settings of a texture transfer (Mesh2Tex section 3.3) and the checks they must pass."""

from __future__ import annotations

from dataclasses import dataclass, field

from mesh2tex.config import check_fields
from mesh2tex.errors import InputError
from mesh2tex.io.assets import check_texture_format
from mesh2tex.nn.nca import NCAConfig

# Ablation name -> the TransferConfig fields it changes (paper Table 8), and "paper": the paper's
# own losses and step (style losses alone, unlit renders), without what this project adds.
ABLATIONS = {
    "full": {},
    "no_noc": {"use_noc": False},
    "no_patches": {"use_patches": False},
    "no_refine": {"refine": False},
    "no_mirror": {"w_mirror": 0.0},
    "paper": {"w_colour": 0.0, "light": "off", "lr": 1e-2, "refine_lr": 0.0, "w_mirror": 0.0},
}

LIGHT_MODES = ("auto", "learn", "off")
LIGHT_STARTS = ("prior", "search")
LATENT_SPACES = ("w_plus", "w")


@dataclass
class AutomatonFitConfig:
    iters: int = 300  # Adam steps
    steps_min: int = 15  # growth per iteration: uniform in [steps_min, steps_max]
    steps_max: int = 25
    final_steps: int = 20  # growth of the result
    lr: float = 2e-3  # Adam learning rate (gradients normalised per parameter, as train nca)
    overflow_weight: float = 10.0
    nca: NCAConfig = field(default_factory=NCAConfig)

    def __post_init__(self):
        check_fields(
            self,
            at_least={"iters": 1, "steps_min": 1, "steps_max": 1, "final_steps": 1, "overflow_weight": 0},
            positive=("lr",),
        )
        if self.steps_max < self.steps_min:
            raise ValueError(f"steps_max {self.steps_max} is below steps_min {self.steps_min}")


@dataclass
class TransferConfig:
    resolution: int = 128  # side of the photo crop and of the optimised renders
    latent_iters: int = 100  # stage 1: iterations on the latent w (paper: 100)
    refine_iters: int = 300  # stage 2: iterations on the last two synthesis blocks (paper: 300)
    refine_blocks: int = 2  # synthesis blocks unfrozen in stage 2 (paper: 2)
    # stage 1 optimises one w per style input (w_plus, the paper's) or one w shared by all of them (w: stays on
    # the generator's manifold)
    latent_space: str = "w_plus"
    # candidate starts of stage 1: the mean latent and latent_starts - 1 seeded samples (truncation 0.7); the one
    # whose render scores the lowest loss is kept
    latent_starts: int = 1
    lr: float = 5e-2  # Adam learning rate of stage 1, and of stage 2 unless refine_lr is set (paper: 1e-2 for both)
    refine_lr: float = 1e-2  # Adam learning rate of stage 2 (0: lr)
    w_glob: float = 1.0  # weight of the global style loss
    w_patch: float = 1.0  # weight of the patch style loss
    # resolution levels of the global style loss, and of the patch loss when patch_scales is 0 (paper: 3)
    scales: int = 3
    patches: int = 2  # patch pairs per iteration (paper: 2)
    # side of a patch in pixels (paper: 64; at 128 px crops 32 beats it, docs/results/protocols.md)
    patch_size: int = 32
    # resolution levels of the patch loss alone (0: ``scales``; 2 keeps 32 px patches at a 16 px coarsest level)
    patch_scales: int = 2
    # weight of the low-pass colour loss: render against photo at the pose, both blurred, where both show the
    # object (0: the paper's style losses alone)
    w_colour: float = 10.0
    colour_sigma: float = 0.03  # the colour loss's Gaussian blur, as a share of the crop side (0.03: 2 px at 64 px)
    # stage 2: weight of the low-pass colour loss that keeps the surfaces the photo does not show as stage 1
    # painted them (0: off)
    w_anchor: float = 0.0
    # views of those surfaces for w_anchor, evenly spaced in azimuth from 30 degrees after the photo's; one per
    # stage-2 iteration, in turn
    anchor_views: int = 6
    # both stages: weight of the photo read across the mesh's mirror plane, when the mesh has one (a chair's or a
    # car's left and right): the flipped photo against the render at the mirrored pose (0: off)
    w_mirror: float = 1.0
    # the photo's light in the renders: learn (a directional light and ambient, found as light_start says and
    # optimised with the texture unless light_fixed; the texture stays albedo), off (unlit renders), auto (learn
    # when the generator was trained lit)
    light: str = "auto"
    # where the photo's light starts: search (the light of the prior that best explains the photo's shading across
    # the mesh's folds at the found pose, mesh2tex.transfer.light.search_light) or prior (the light prior's middle)
    light_start: str = "search"
    # the light stays where it starts (False: optimised with the texture, which splits the photo's shading between
    # the two wrongly on chairs: docs/results/transfer.md)
    light_fixed: bool = True
    # the ambient share the light starts at, whatever light_start finds for its direction (negative: found with
    # the direction by the search, or the prior's middle)
    light_ambient: float = -1.0
    use_noc: bool = True  # NOC-guided patch pairs (False: random pairs, the "w/o NOC" ablation)
    use_patches: bool = True  # patch style loss (False: the "w/o patch loss" ablation)
    refine: bool = True  # stage 2 (False: the "w/o surface features" ablation)
    margin: float = 0.1  # crop margin around the object, as a share of its larger side
    # --pose auto: pick the pose whose silhouette best matches the photo's mask (False: the network's bin centres,
    # as the paper)
    pose_search: bool = True
    # azimuth spacing of the silhouette search in degrees (then one finer pass at half of it)
    pose_search_step: float = 10.0
    pose_search_elevations: int = 2  # elevation bins searched: the network's most likely ones
    # the search keeps to the pose network's most likely azimuth bin when the best silhouette there is within this
    # much IoU of the best anywhere: a car's outline barely tells its front from its back, the network mostly can
    # (negative: silhouettes alone decide)
    pose_search_tie: float = 0.02
    # then the found pose's half turn, where its best silhouette is within this much IoU of the found one's, wins
    # if the creases the mesh's faces draw there agree better with the photo's edges (:func:`mesh2tex.transfer.pose.
    # crease_agreement`): a car's outline barely tells its front from its back, its windscreen and bonnet do
    # (negative: no such check)
    pose_halfturn_tie: float = 0.05
    # an estimated mask is made again by GrabCut from the mesh's outline at the found pose, and the pose found
    # again
    mask_refine: bool = True
    render_oversample: float = 1.5  # render at this multiple of ``resolution`` before cropping to the object
    turntable_frames: int = 12  # frames of turntable.gif
    texture_size: int = 1024  # side of the baked UV texture in textured.glb
    texture_format: str = "png"  # how the GLB embeds it: png (lossless), jpeg or webp (lossy, smaller)
    # finest quad count when a raw mesh is prepared on the fly (0: the hierarchy the model was trained on)
    faces: int = 0
    seed: int = 0  # seed of the initial latent and the patch sampling
    device: str = "auto"  # auto, cpu or cuda
    vgg_weights: str = ""  # VGG19 ImageNet weights file ('' looks in $TORCH_HOME, else a random-weight fallback)
    # infer transfer --automaton: the automaton fitted instead of the GAN's texture
    automaton: AutomatonFitConfig = field(default_factory=AutomatonFitConfig)

    def __post_init__(self):
        check_texture_format(self.texture_format)
        check_fields(
            self,
            positive=("lr",),
            at_least={
                "latent_iters": 0,
                "refine_iters": 0,
                "refine_lr": 0,
                "w_glob": 0,
                "w_patch": 0,
                "w_colour": 0,
                "patches": 1,
                "refine_blocks": 1,
                "turntable_frames": 1,
                "latent_starts": 1,
                "w_anchor": 0,
                "anchor_views": 1,
                "w_mirror": 0,
                "resolution": 16,
                "texture_size": 16,
                "patch_size": 1,
            },
            between={
                "margin": (0.0, 1.0),
                "render_oversample": (1.0, 4.0),
                "scales": (1, 8),
                "patch_scales": (0, 8),
                "colour_sigma": (0.0, 0.5),
            },
        )
        if self.latent_space not in LATENT_SPACES:
            raise ValueError(f"latent_space {self.latent_space!r}: must be one of {', '.join(LATENT_SPACES)}")
        if self.light not in LIGHT_MODES:
            raise ValueError(f"light {self.light!r}: must be one of {', '.join(LIGHT_MODES)}")
        if self.light_start not in LIGHT_STARTS:
            raise ValueError(f"light_start {self.light_start!r}: must be one of {', '.join(LIGHT_STARTS)}")
        if self.light_ambient >= 1.0 or self.light_ambient == 0.0:
            raise ValueError(f"light_ambient {self.light_ambient}: must be in (0, 1), or negative for searched")
        if not 0 < self.pose_search_step <= 90 or self.pose_search_elevations < 1:
            raise ValueError(
                f"pose_search_step {self.pose_search_step}, pose_search_elevations {self.pose_search_elevations}: "
                "the step must be in (0, 90] degrees and at least one elevation bin searched"
            )

    @property
    def patch_levels(self) -> int:
        """Resolution levels the patch loss uses: ``patch_scales``, or ``scales`` when that is 0."""
        return self.patch_scales or self.scales


def check_style_sizes(cfg: TransferConfig) -> None:
    """InputError unless the crop and the patches keep 16 pixels at the coarsest level of their style losses."""
    if cfg.scales < 1 or cfg.patch_scales < 0:
        raise InputError(
            f"scales {cfg.scales}, patch_scales {cfg.patch_scales}: scales must be at least 1, patch_scales at least 0"
        )
    smallest = 16 * 2 ** (cfg.scales - 1)
    if cfg.resolution < smallest:
        raise InputError(f"--resolution {cfg.resolution}: must be at least {smallest} for {cfg.scales} style scales")
    patch = min(cfg.patch_size, cfg.resolution)  # a patch is clipped to the crop
    if cfg.use_patches and patch < 16 * 2 ** (cfg.patch_levels - 1):
        raise InputError(
            f"patch_size {cfg.patch_size}: a patch of {patch} px keeps fewer than 16 px at its "
            f"{cfg.patch_levels} style scales; use larger patches or fewer patch_scales"
        )
