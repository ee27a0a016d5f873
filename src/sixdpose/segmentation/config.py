"""Typed training / inference configuration of the Mask R-CNN stage, with named profiles.

Three profiles are defined:

``paper``
    Section IV-A of the paper: Mask R-CNN with a ResNet-50-FPN backbone initialised from ImageNet
    weights (when they are in the local torch hub cache), no frozen layers, Adam at 1e-3 decayed by
    10x every 30 epochs, 100 epochs, a seeded random 90/10 image split for the synthetic dataset
    (BOP data: the ``train``/``test`` split directories as given). Images at their native 640x480
    resolution (torchvision's ``min_size``/``max_size`` set so a 640x480 image is not rescaled at test
    time). Augmentation (not specified by the paper, chosen here): photometric colour jitter and
    multi-scale training (the shorter side is drawn from ``train_min_sizes`` each step, i.e. scales
    0.8x..1.2x).

``smoke``
    The same code path, sized for a CPU continuous-integration run of a few minutes: images resized
    to a shorter side of 200 px (multi-scale 180-220 in training) with anchors halved accordingly
    (16-256 px), a ResNet-18-FPN with 64 channels and lighter heads, random init (no download is
    attempted), 40 epochs of at most 3 steps of 2 images (<= 120 steps, about 1-1.5 min on one core).
    On the 6-image smoke dataset it overfits its training images (mask AP50 about 0.7-0.85).

``cpu``
    The smoke network at a larger scale for a 2-core CPU: images at a shorter side of 320 px
    (multi-scale 288-352), 300 RPN proposals and 128 sampled RoIs per training image, 2 full epochs
    (lr /10 after the first), one data-loading worker. On the 1,200-image ``train`` split it is 1,080
    steps of 2 images: about 25 min on two free cores, 35-60 min when another job shares them (use
    ``--threads 1`` then: two torch threads on one free core run several times slower).

A config is saved as ``config.json`` in the run directory and read back on ``--resume`` and by
inference, so a run always records exactly what trained it.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..config import bounded, from_profile, path_name
from ..constants import DETECTION_SCORE_FLOOR
from ..constants import SEG_BACKBONES as BACKBONES
from ..training.schedule import TrainSchedule


@dataclass(frozen=True)
class SegConfig(TrainSchedule):
    """Every setting of a segmentation run (see the module docstring for the named profiles).

    Model:
        backbone: ``resnet50`` (paper), ``resnet34``, ``resnet18``, or ``mobilenet_v3_large`` /
            ``mobilenet_v3_small`` (torchvision's MobileNetV3 features: a lighter network for a CPU, with
            the feature pyramid on the last block of each of its stride-4 to stride-32 stages).
        pretrained: initialise the backbone with ImageNet weights if they are in the local torch hub
            cache (never downloaded here; ``sixdpose fetch-weights`` puts them there); otherwise random
            initialisation, said in one line.
        trainable_layers: backbone stages left trainable, counted from the deepest (5 = none frozen, as
            the paper; a MobileNet's stages are its stem and its stride-4, -8, -16 and -32 blocks).
        fpn_channels: FPN output channels (torchvision default 256).
        box_head_dim: hidden size of the two-layer box head (torchvision default 1024).
        mask_head_channels: channels of each of the 4 conv layers of the mask head (default 256).
        min_size, max_size: test-time resize of the shorter / longer image side (pixels).
        train_min_sizes: shorter sides drawn at random per training step (multi-scale augmentation).
        anchor_sizes: RPN anchor size (pixels, after resizing) of each of the 5 FPN levels; aspect
            ratios 0.5, 1, 2 (torchvision defaults).
        rpn_pre_nms_train, rpn_post_nms_train, rpn_pre_nms_test, rpn_post_nms_test: RPN proposals.
        rpn_batch_size, box_batch_size: sampled anchors / RoIs per image for the losses.
        detections_per_img: detections kept per image.
        score_thresh: minimum score of a returned detection (low, so AP sees the full curve;
            consumers of the masks apply their own threshold).

    Schedule (:class:`~sixdpose.training.schedule.TrainSchedule`, shared by every network): epochs,
        batch_size (images per step and process; 4 here), lr, warmup_steps, lr_step_epochs and
        lr_gamma (x0.1 every 30 epochs here, the paper's decay), weight_decay, grad_clip (10 here),
        amp, time_budget, max_steps_per_epoch, seed (also the split), num_workers, num_threads,
        log_every (1 here), ema_decay (the weight average, 0: off).

    Data:
        val_fraction: share of synthetic images held out for testing (seeded random split).
        split_by: ``image`` (the paper) or ``scene`` (no scene in both parts).
        train_split, test_split: BOP split directories used for training / testing.
        min_mask_pixels: instances with fewer visible pixels are dropped from training (logged).
        color_jitter: (brightness, contrast, saturation, hue) strengths; all 0 disables it.
        hflip_prob: horizontal flip probability (0: mirrored text and handedness would teach wrong
            appearances; not used by the paper).

    Misc:
        profile: the profile the config came from.
    """

    profile: str = "paper"
    # model
    backbone: str = "resnet50"
    pretrained: bool = True
    trainable_layers: int = bounded(5, min=0, max=5)
    fpn_channels: int = bounded(256, min=1, max=4096)
    box_head_dim: int = bounded(1024, min=1, max=65536)
    mask_head_channels: int = bounded(256, min=1, max=4096)
    min_size: int = bounded(480, min=1, max=8192)
    max_size: int = bounded(800, min=1, max=8192)
    train_min_sizes: tuple[int, ...] = bounded((384, 416, 448, 480, 512, 544, 576), min=1, max=8192)
    anchor_sizes: tuple[int, ...] = bounded((32, 64, 128, 256, 512), min=1, max=8192)
    rpn_pre_nms_train: int = bounded(2000, min=1, max=100_000)
    rpn_post_nms_train: int = bounded(2000, min=1, max=100_000)
    rpn_pre_nms_test: int = bounded(1000, min=1, max=100_000)
    rpn_post_nms_test: int = bounded(1000, min=1, max=100_000)
    rpn_batch_size: int = bounded(256, min=1, max=100_000)
    box_batch_size: int = bounded(512, min=1, max=100_000)
    detections_per_img: int = bounded(100, min=1, max=10_000)
    score_thresh: float = bounded(DETECTION_SCORE_FLOOR, min=0)  # above 1: nothing passes (a test uses it)
    # schedule defaults that differ from TrainSchedule's
    batch_size: int = bounded(4, min=1, max=1024)
    lr_step_epochs: int = bounded(30, min=1, max=100_000)
    lr_gamma: float = bounded(0.1, min=0, max=1, min_open=True)
    grad_clip: float = bounded(10.0, min=0, max=1e6)
    log_every: int = bounded(1, min=1, max=1_000_000)
    # data
    split_by: str = "image"
    val_fraction: float = bounded(0.1, min=0, max=1, max_open=True)
    train_split: str = path_name("train")
    test_split: str = path_name("test")
    min_mask_pixels: int = bounded(1, min=0, max=10_000_000)
    color_jitter: tuple[float, float, float, float] = bounded((0.3, 0.3, 0.3, 0.03), min=0, max=10)
    hflip_prob: float = bounded(0.0, min=0, max=1)

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first invalid field."""
        super().validate()
        if self.backbone not in BACKBONES:
            raise ValueError(f"backbone: {self.backbone!r} is not one of {sorted(BACKBONES)}")
        if not 0 <= self.trainable_layers <= 5:
            raise ValueError(f"trainable_layers: {self.trainable_layers} is not in 0..5")
        if not 0.0 <= self.val_fraction < 1.0:
            raise ValueError(f"val_fraction: {self.val_fraction} is not in [0, 1)")
        if self.split_by not in ("image", "scene"):
            raise ValueError(f"split_by: {self.split_by!r} is not 'image' or 'scene'")
        for name in ("min_size", "max_size"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name}: must be >= 1, got {getattr(self, name)}")
        if len(self.anchor_sizes) != 5:
            raise ValueError("anchor_sizes: expected one size per FPN level (5)")
        if not self.train_min_sizes:
            raise ValueError("train_min_sizes: must not be empty")
        if len(self.color_jitter) != 4:
            raise ValueError("color_jitter: expected (brightness, contrast, saturation, hue)")


#: Named profiles (see the module docstring).
PROFILES: dict[str, SegConfig] = {
    "paper": SegConfig(profile="paper"),
    "smoke": SegConfig(
        profile="smoke",
        backbone="resnet18",
        pretrained=False,
        trainable_layers=5,
        fpn_channels=64,
        box_head_dim=256,
        mask_head_channels=64,
        min_size=200,
        max_size=400,
        train_min_sizes=(180, 200, 220),
        anchor_sizes=(16, 32, 64, 128, 256),
        rpn_pre_nms_train=300,
        rpn_post_nms_train=150,
        rpn_pre_nms_test=300,
        rpn_post_nms_test=100,
        rpn_batch_size=128,
        box_batch_size=64,
        detections_per_img=50,
        epochs=40,
        batch_size=2,
        lr=1e-3,
        lr_step_epochs=30,
        max_steps_per_epoch=3,
        val_fraction=0.1,
        num_workers=0,
        num_threads=1,
        color_jitter=(0.1, 0.1, 0.1, 0.0),
    ),
}
PROFILES["cpu"] = PROFILES["smoke"].replace(
    profile="cpu", min_size=320, max_size=427, train_min_sizes=(288, 320, 352), rpn_post_nms_train=300,
    box_batch_size=128, epochs=2, lr_step_epochs=1, max_steps_per_epoch=0, num_workers=1, num_threads=0)


def profile_config(name: str, **overrides) -> SegConfig:
    """The config of profile ``name`` with ``overrides`` applied; raises
    :class:`~sixdpose.errors.ConfigError` for an unknown profile, field or value."""
    return from_profile(PROFILES, name, overrides)


__all__ = ["BACKBONES", "PROFILES", "SegConfig", "profile_config"]
