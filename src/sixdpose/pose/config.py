"""Typed configuration of the learned pose stage (paper section IV-C), with named profiles.

Profiles (``PROFILES`` for the main network, ``REFINER_PROFILES`` for the refiner):

``paper``
    Section IV-C at full scale (GPU): full 640x480 image through the PSPNet/ResNet-18 (``crop = 0``),
    width 1 (the 1408-channel fusion), up to 500 sampled pixels and 500 model points, Adam 1e-4 with
    an exponential warm-up over 1,000 steps and the learning rate multiplied by 0.6 every 5 epochs,
    100 epochs, uniform RGB noise of +-0.3 (on [0, 1] colours) in training. Refiner: Adam 1e-3, x0.6
    every 10 epochs, 100 epochs, 2 unrolled iterations.

``cpu``
    The best this 2-core CPU machine can do in at most 2 hours for both networks together on a
    generated ``train`` split: 64x64 crops around each mask's box, width 0.25, 256 points, a 6D
    rotation, the translation as the model-box centre's offset from the masked cloud's centroid
    (``translation = centroid_offset``), the learning rate x0.6 every 2 epochs, and time budgets of
    40 min (main net) and 15 min (refiner) of training. The dense head's fit takes inliers within 6 cm
    (``ransac_threshold = 0.06``): a network trained this briefly predicts coordinates a few centimetres off,
    and the 1.5 cm of the other profiles then keeps too few points (chosen on the real sample's scene
    000000 with the ``dense2_e12`` run: 10 % -> 51.67 % alone; 4.5 cm to 1 m gave the same).

``smoke``
    Continuous integration: 32x32 crops, width 1/16, 64 points, 64 model points, the first 4 images
    visited 4 times per epoch, 120 epochs at lr 1e-2 (x0.3 after 60); overfits a handful of instances
    (rotations within ~60 degrees of the identity: ADD regression from scratch needs far longer to
    escape the local minima of large rotations) in about 30 s on one core.

Refiner training noise (documented here, the paper gives no values): the main network's pose is
perturbed by a rotation about a uniformly random axis by an angle drawn from N(0, ``noise_rot_deg``)
degrees and a translation offset drawn from N(0, ``noise_trans``) metres per axis.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..config import bounded, from_profile
from ..training.schedule import TrainSchedule

TRANSLATIONS = ("absolute", "centroid_offset")
ROTATIONS = ("quaternion", "6d")
NORMS = ("none", "group", "batch")
HEADS = ("paper", "dense")
#: what the network sees of the image: the paper's CNN embedding, or nothing (geometry alone; dense head)
APPEARANCES = ("cnn", "local", "local_rgb", "none")
#: how the dense head names a shape flip at inference (PoseConfig.flip_choice)
FLIP_CHOICES = ("auto", "classifier", "colour")
#: the frame the dense head sees the centred cloud in (PoseConfig.input_frame)
INPUT_FRAMES = ("camera", "pca")
#: how training picks the canonical shape flip of a pose (PoseConfig.flip_canon)
FLIP_CANONS = ("frame", "view")
DENSE_LOSSES = ("densefusion", "decoupled")


@dataclass(frozen=True)
class FrameSchedule(TrainSchedule):
    """The training schedule plus the frame sampling that both pose networks share (base of
    :class:`PoseConfig` and :class:`RefinerConfig`, where the fields are described).

    Schedule: epochs, batch_size, lr, warmup_steps, lr_step_epochs, lr_gamma, weight_decay, grad_clip,
        amp, time_budget, max_steps_per_epoch, seed, num_workers, num_threads, log_every, ema_decay
        (:class:`~sixdpose.training.schedule.TrainSchedule`).
    Frames: num_points, num_model_points, min_points, max_images, repeat.
    Model: width (channel multiplier, > 0).
    """

    width: float = bounded(1.0, min=0, max=16, min_open=True)
    num_points: int = bounded(500, min=1, max=100_000)
    num_model_points: int = bounded(500, min=1, max=100_000)
    min_points: int = bounded(10, min=1, max=100_000)
    max_images: int = bounded(0, min=0, max=100_000_000)
    repeat: int = bounded(1, min=1, max=10_000)


@dataclass(frozen=True)
class PoseConfig(FrameSchedule):
    """Every setting of a main pose network run (see the module docstring for the profiles).

    Model:
        width: channel multiplier of every layer (1 = the paper: 1408-channel fusion, PSP to 1024).
        emb_dim: per-pixel colour embedding size of the PSPNet (32).
        crop: 0 = the full image through the CNN (the paper); N > 0 = a square crop around each mask's
            box (enlarged by ``crop_margin``), resized to N x N pixels (a multiple of 8), as DenseFusion.
        crop_margin: relative enlargement of the mask box before cropping (0.1 = 10 % per side).
        translation: ``absolute`` (camera-frame translation, the paper) or ``centroid_offset``
            (the position of the model's box centre as an offset from the masked cloud's centroid, then
            ``t = centre - R c_O``; the cloud is centred before the point net and both are expressed in
            units of 5 cm, ``model.OFFSET_SCALE``).
        rotation: ``quaternion`` (normalised, the paper) or ``6d`` (Zhou et al. 2019, Gram-Schmidt).
        norm: ``none`` (the paper: no normalisation layers), ``group`` (GroupNorm) or ``batch``
            (BatchNorm) after every convolution of the CNN and the point branches.
        head: ``paper`` (rotation and translation regression, section IV-C) or ``dense`` (the project's
            own: per-point object coordinates and confidences, the pose by RANSAC + weighted Kabsch;
            :mod:`sixdpose.pose.dense`; ``translation`` and ``rotation`` are then unused).
        dense_loss: the dense head's loss, ``densefusion`` (``mean(d c - w log c)``) or ``decoupled`` (the
            coordinates on the plain mean distance, the confidences on the DenseFusion term with the
            distances detached; :func:`~sixdpose.pose.dense.dense_loss`).
        ransac_threshold: inlier distance (metres) of the dense head's robust fit at inference.
        ransac_iterations: hypotheses of that fit.
        flips: the dense head's shape flips (0: none, the first dense recipe). N > 0: for every class flagged
            asymmetric whose shape is symmetric (a box turned by 180 degrees, a can upside down: the turns
            that only texture tells apart, :func:`~sixdpose.pose.dense.shape_flips`, at most N of them, the
            identity included), the coordinates are regressed in the frame of one canonical turn (a function
            of what the image shows, so learnable from geometry) and a per-point classifier, averaged over the
            points, names which turn is the true pose (cross-entropy weighted by ``flip_weight``); inference
            fits the canonical frame and applies the classified turn.
        flip_weight: weight of that classification loss beside the coordinate loss (metres).
        appearance: what the per-point embedding fused with the points is: ``cnn`` (the paper: per-pixel
            CNN embeddings of the image), ``local`` (the dense head on geometry alone: no CNN, the embedding
            is the local shape around each point, two EdgeConv layers over its 16 nearest neighbours,
            :class:`~sixdpose.pose.model.LocalGeometry`), ``local_rgb`` (that embedding with each point's pixel
            colour, standardised per instance, in its first layer: the local texture without a CNN) or
            ``none`` (no CNN and a zero embedding: the plain PointNet, an ablation). Without the CNN a run
            trains faster and what it learns from rendered depth does not hinge on how rendered colours look,
            but a flip cannot be learnt from geometry (its turns differ only in texture): use ``flips``, whose
            turn inference then names from the object model's colours (``flip_choice``).
        flip_choice: how inference names the shape flip (``flips`` > 0): ``classifier`` (the network's flip
            classifier), ``colour`` (each turn of the fitted pose scored by how well the model's colours
            agree with the masked points', :func:`~sixdpose.registration.verify.colour_scores`, after ICP
            of the fitted pose when ``predict-pose --icp``; the classifier where the model has no colours)
            or ``auto`` (``colour`` without the CNN,
            ``classifier`` with it).
        colour_slides: with the turns named by colour (``flip_choice``), also score each turn slid along an
            elongated model's longest principal axis by ``k x verify_slide_rel`` x its extent along it,
            ``k = +-1 .. +-colour_slides``, for a model at least ``verify_slide_min_elong`` times as long
            along it as along the second (the verification's slides,
            :func:`~sixdpose.registration.hypotheses.slides`, settings from
            :data:`~sixdpose.registration.LEARNED_VERIFY`), and keep the best: a partly hidden bottle's
            visible part matches its body's geometry at its middle as well as at its end, its print does
            not. 0: no slides (every run before session 29). An inference field (``predict-pose --set
            colour_slides=N``); the default 3 was chosen by a rule fixed before its scores, on generated
            frames and the YCB-Video sample's tuning scene (docs/pose.md, "Slides named by colour").
        input_frame: the frame in which the dense head sees the centred cloud: ``camera`` (as sampled) or
            ``pca`` (turned into the cloud's own principal axes, :func:`~sixdpose.pose.model.pca_frame`, so
            the input no longer changes when the object turns with respect to the camera and the
            coordinates it must give back, which live in the object's frame, do not either; the canonical
            shape flip is chosen in that frame too). The pose is still fitted to the camera-frame cloud.
        flip_canon: which turn of a shape flip training regresses (``flips`` > 0): ``frame`` (the turn whose
            axes are closest to those of the frame the network sees the cloud in,
            :func:`~sixdpose.pose.dense.canonical_flip`) or ``view`` (the turn that puts the camera on a fixed
            side of the object, :func:`~sixdpose.pose.dense.view_flip`: defined by the seen faces, so also for a
            cube, whose principal axes are arbitrary). Inference is the same for both.

    Data:
        num_points: masked pixels with valid depth sampled per instance (fewer: wrapped repeats).
        num_model_points: model points of the loss (a fresh random subset every step).
        min_points: instances with fewer valid depth pixels are skipped in training and get a
            score-0 row at inference.
        rgb_noise: uniform per-pixel noise amplitude added to [0, 1] colours in training (0: none).
        colour_jitter: per-image colour transform in training (0: none; 0.3: brightness x U(0.7, 1.3),
            per-channel gains x U(0.85, 1.15), gamma exp(U(-0.3, 0.3))): another camera's white balance,
            exposure and response, for networks meant to run on real frames
            (:func:`~sixdpose.pose.data.normalise_images`).
        mask_jitter_px, depth_noise, depth_holes, crop_jitter: training augmentation of each instance's
            mask (eroded or dilated by up to N pixels), depth (Gaussian axial noise up to this many metres;
            random holes up to this fraction of the mask) and crop window (relative shift and scale), as
            real frames and predicted masks differ from rendered ones (:class:`~sixdpose.pose.data.Augment`;
            0: none, the paper).
        occlusion: training augmentation: for half the instances, up to this fraction of the mask is hidden
            beyond a straight edge in a random direction (an occluder in front; 0: none, the paper).
        max_images: train on the first N images only (0: all; the smoke profile uses a handful).
        repeat: each image is visited ``repeat`` times per epoch.

    Schedule (:class:`~sixdpose.training.schedule.TrainSchedule`, shared by every network): epochs,
        batch_size (images per step and process; every instance of each image is in the step), lr
        (Adam; 1e-4 here), warmup_steps (exponential warm-up from lr/1000 to lr; 1000 here),
        lr_step_epochs and lr_gamma (learning rate x lr_gamma every lr_step_epochs epochs; 5 here),
        weight_decay, grad_clip, amp, time_budget (seconds; once spent the epoch is validated and
        checkpointed as done and training stops), max_steps_per_epoch, seed, num_workers,
        num_threads, log_every, ema_decay (the weight average, 0: off).

    Misc:
        profile: the profile the config came from.
    """

    profile: str = "paper"
    emb_dim: int = bounded(32, min=1, max=4096)
    crop: int = bounded(0, min=0, max=4096)
    crop_margin: float = bounded(0.1, min=0, max=10)
    translation: str = "absolute"
    rotation: str = "quaternion"
    norm: str = "none"
    head: str = "paper"
    dense_loss: str = "densefusion"
    ransac_threshold: float = bounded(0.015, min=0, max=1, min_open=True)
    ransac_iterations: int = bounded(128, min=1, max=100_000)
    flips: int = bounded(0, min=0, max=64)
    flip_weight: float = bounded(0.1, min=0, max=100)
    appearance: str = "cnn"
    flip_choice: str = "auto"
    colour_slides: int = bounded(3, min=0, max=20)
    input_frame: str = "camera"
    flip_canon: str = "frame"
    rgb_noise: float = bounded(0.3, min=0, max=1)
    colour_jitter: float = bounded(0.0, min=0, max=1, max_open=True)
    mask_jitter_px: int = bounded(0, min=0, max=64)
    depth_noise: float = bounded(0.0, min=0, max=0.1)
    depth_holes: float = bounded(0.0, min=0, max=0.9)
    crop_jitter: float = bounded(0.0, min=0, max=0.5)
    occlusion: float = bounded(0.0, min=0, max=0.9)
    lr: float = bounded(1e-4, min=0, max=10, min_open=True)
    warmup_steps: int = bounded(1000, min=0, max=100_000_000)
    lr_step_epochs: int = bounded(5, min=1, max=100_000)

    def validate(self) -> None:
        """Check every field (ValueError naming the field)."""
        super().validate()
        if self.crop < 0 or self.crop % 8:
            raise ValueError(f"crop must be 0 or a positive multiple of 8, got {self.crop}")
        if self.translation not in TRANSLATIONS:
            raise ValueError(f"translation must be one of {TRANSLATIONS}, got {self.translation!r}")
        if self.rotation not in ROTATIONS:
            raise ValueError(f"rotation must be one of {ROTATIONS}, got {self.rotation!r}")
        if self.norm not in NORMS:
            raise ValueError(f"norm must be one of {NORMS}, got {self.norm!r}")
        if self.head not in HEADS:
            raise ValueError(f"head must be one of {HEADS}, got {self.head!r}")
        if self.dense_loss not in DENSE_LOSSES:
            raise ValueError(f"dense_loss must be one of {DENSE_LOSSES}, got {self.dense_loss!r}")
        if self.appearance not in APPEARANCES:
            raise ValueError(f"appearance must be one of {APPEARANCES}, got {self.appearance!r}")
        if self.appearance != "cnn" and self.head != "dense":
            raise ValueError(f"appearance={self.appearance!r} needs head=dense, got head={self.head!r}")
        if self.flip_choice not in FLIP_CHOICES:
            raise ValueError(f"flip_choice must be one of {FLIP_CHOICES}, got {self.flip_choice!r}")
        if self.flip_canon not in FLIP_CANONS:
            raise ValueError(f"flip_canon must be one of {FLIP_CANONS}, got {self.flip_canon!r}")
        if self.input_frame not in INPUT_FRAMES:
            raise ValueError(f"input_frame must be one of {INPUT_FRAMES}, got {self.input_frame!r}")
        if self.input_frame != "camera" and self.head != "dense":
            raise ValueError(f"input_frame={self.input_frame!r} needs head=dense, got head={self.head!r}")
        if self.flips and self.head != "dense":
            raise ValueError(f"flips needs head=dense, got head={self.head!r}")
        if not self.ransac_threshold > 0 or self.ransac_iterations < 1:
            raise ValueError("ransac_threshold must be > 0 and ransac_iterations >= 1")
        if self.emb_dim < 1 or self.rgb_noise < 0:
            raise ValueError("emb_dim must be >= 1 and rgb_noise >= 0")
        if not 0 <= self.colour_jitter < 1:
            raise ValueError(f"colour_jitter must be in [0, 1), got {self.colour_jitter}")

    def arch(self) -> dict:
        """The fields that define the network's shapes (checked when loading weights)."""
        arch = {k: getattr(self, k) for k in ("width", "emb_dim", "crop", "translation", "rotation", "norm")}
        if self.head != "paper":  # the paper head's arch is unchanged (checkpoints from before the field)
            arch["head"] = self.head
        if self.flips:  # likewise the dense head's without flips
            arch["flips"] = self.flips
        if self.appearance != "cnn":  # likewise the networks with a CNN
            arch["appearance"] = self.appearance
        if self.input_frame != "camera":  # likewise the networks that see the camera frame
            arch["input_frame"] = self.input_frame
        return arch


@dataclass(frozen=True)
class RefinerConfig(FrameSchedule):
    """Every setting of an iterative-refiner run (trained on a finished main network's poses).

    Model:
        width: channel multiplier (1 = DenseFusion's 384->512->1024, heads 1024->512->128).
        iterations: refinement iterations unrolled in training (loss on the final pose) and the
            default at inference (the paper: 2).
    Noise (added to the main net's poses in training; see the module docstring):
        noise_rot_deg: std of the rotation angle (degrees) about a random axis.
        noise_trans: std of the translation offset per axis (metres).
    Data: num_points, num_model_points, min_points, max_images, repeat as in :class:`PoseConfig`.
    Schedule (:class:`~sixdpose.training.schedule.TrainSchedule`, its defaults: lr 1e-3, no warm-up,
        x0.6 every 10 epochs): epochs, batch_size, lr, warmup_steps, lr_step_epochs, lr_gamma,
        weight_decay, grad_clip, amp, time_budget, max_steps_per_epoch, seed, num_workers,
        num_threads, log_every, ema_decay (the weight average, 0: off).
    Misc: profile as in :class:`PoseConfig`.
    """

    profile: str = "paper"
    iterations: int = bounded(2, min=1, max=100)
    noise_rot_deg: float = bounded(15.0, min=0, max=180)
    noise_trans: float = bounded(0.02, min=0, max=10)

    def validate(self) -> None:
        """Check every field (ValueError naming the field)."""
        super().validate()
        if self.iterations < 1:
            raise ValueError(f"iterations must be >= 1, got {self.iterations}")
        if self.noise_rot_deg < 0 or self.noise_trans < 0:
            raise ValueError("noise_rot_deg and noise_trans must be >= 0")

    def arch(self) -> dict:
        """The fields that define the refiner's shapes."""
        return {"width": self.width}


PROFILES: dict[str, PoseConfig] = {
    "paper": PoseConfig(),
    "cpu": PoseConfig(profile="cpu", width=0.25, crop=64, num_points=256, num_model_points=256, rgb_noise=0.1,
                      translation="centroid_offset", rotation="6d", epochs=40, batch_size=4, lr=1e-3, warmup_steps=200,
                      lr_step_epochs=2, lr_gamma=0.6, amp=False, time_budget=40 * 60.0, num_workers=1, num_threads=2,
                      ransac_threshold=0.06),
    "smoke": PoseConfig(profile="smoke", width=1 / 16, crop=32, num_points=64, num_model_points=64, rgb_noise=0.0,
                        max_images=4, repeat=4, epochs=120, batch_size=4, lr=1e-2, warmup_steps=0,
                        lr_step_epochs=60, lr_gamma=0.3, amp=False, num_workers=0, num_threads=1, log_every=5),
}

REFINER_PROFILES: dict[str, RefinerConfig] = {
    "paper": RefinerConfig(),
    "cpu": RefinerConfig(profile="cpu", width=0.25, num_points=256, num_model_points=256, epochs=20, batch_size=4,
                         lr=1e-3, lr_step_epochs=6, amp=False, time_budget=15 * 60.0, num_workers=1, num_threads=2),
    "smoke": RefinerConfig(profile="smoke", width=1 / 16, num_points=64, num_model_points=64, max_images=4, repeat=4,
                           epochs=3, batch_size=2, lr=1e-3, lr_step_epochs=100, amp=False, num_workers=0,
                           num_threads=1, log_every=5),
}


def profile_config(name: str, overrides: dict | None = None) -> PoseConfig:
    """The main network's named profile with ``overrides`` applied (ConfigError if invalid)."""
    return from_profile(PROFILES, name, overrides)


def refiner_profile_config(name: str, overrides: dict | None = None) -> RefinerConfig:
    """The refiner's named profile with ``overrides`` applied (ConfigError if invalid)."""
    return from_profile(REFINER_PROFILES, name, overrides)
