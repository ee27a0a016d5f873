"""Mask R-CNN construction (torchvision) from a :class:`~.config.SegConfig`.

With the ``paper`` config (ResNet-50, 256 FPN channels, default heads) the network is exactly
torchvision's ``maskrcnn_resnet50_fpn`` with ``num_classes = n_objects + 1`` and
``trainable_backbone_layers=5``. Pretrained ImageNet weights are taken from the local torch hub cache
only (``$TORCH_HOME/hub/checkpoints``, where ``sixdpose fetch-weights`` puts them); this module never
downloads anything.
"""

from __future__ import annotations

import logging
import os
from collections import OrderedDict

from torch import nn

from ..assets.weights import cached_weights_path, imagenet_weights
from .config import SegConfig


def build_model(
    cfg: SegConfig, num_classes: int, *, init: str | None = None, verbose: bool = True
) -> tuple[nn.Module, str]:
    """Build a torchvision ``MaskRCNN`` for ``num_classes`` object classes (+ background).

    Args:
        cfg: the run configuration.
        num_classes: number of object classes, background excluded.
        init: ``None`` to initialise a new model: ImageNet backbone weights from the local cache when
            ``cfg.pretrained`` and the file is there (a missing file is reported in one line on the
            ``sixdpose`` logger, and the backbone starts from random initialisation); or the ``init``
            recorded in a checkpoint (``"imagenet"``/``"random"``) to rebuild the same layout without
            loading anything (the weights come from the checkpoint).
        verbose: log the missing-weights line (False on all but one of several processes).
    Returns:
        ``(model, init)`` where ``init`` is ``"imagenet"`` or ``"random"``. As in torchvision, an
        ImageNet-initialised backbone keeps its BatchNorm statistics frozen; a randomly initialised one
        trains them (``BatchNorm2d``).
    """
    from torchvision.models.detection import MaskRCNN
    from torchvision.models.detection.anchor_utils import AnchorGenerator
    from torchvision.models.detection.backbone_utils import BackboneWithFPN
    from torchvision.models.detection.faster_rcnn import FastRCNNPredictor, TwoMLPHead
    from torchvision.models.detection.mask_rcnn import MaskRCNNHeads, MaskRCNNPredictor
    from torchvision.ops import misc as misc_nn_ops
    from torchvision.ops.feature_pyramid_network import LastLevelMaxPool

    if num_classes < 1:
        raise ValueError("num_classes must be >= 1")
    weights = None
    if init is None:
        init = "random"
        if cfg.pretrained:
            path = cached_weights_path(cfg.backbone)
            if os.path.isfile(path):
                weights = imagenet_weights(cfg.backbone)
                init = "imagenet"
            elif verbose:
                logging.getLogger("sixdpose").warning(
                    "ImageNet weights for %s not in the local torch hub cache (%s; `sixdpose fetch-weights "
                    "--backbone %s` downloads them); training starts from random initialisation",
                    cfg.backbone,
                    path,
                    cfg.backbone,
                )
    elif init not in ("imagenet", "random"):
        raise ValueError(f"init must be 'imagenet' or 'random', not {init!r}")
    norm_layer = misc_nn_ops.FrozenBatchNorm2d if init == "imagenet" else nn.BatchNorm2d
    if cfg.backbone.startswith("mobilenet"):
        body, in_channels, return_layers = _mobilenet_body(cfg, weights, norm_layer)
    else:
        body, in_channels, return_layers = _resnet_body(cfg, weights, norm_layer)
    backbone = BackboneWithFPN(body, return_layers, in_channels, cfg.fpn_channels, extra_blocks=LastLevelMaxPool())

    n = num_classes + 1
    C = cfg.fpn_channels
    res = 7  # RoIAlign output of the box branch (torchvision default)
    box_head = TwoMLPHead(C * res * res, cfg.box_head_dim)
    box_predictor = FastRCNNPredictor(cfg.box_head_dim, n)
    mask_head = MaskRCNNHeads(C, [cfg.mask_head_channels] * 4, 1)
    mask_predictor = MaskRCNNPredictor(cfg.mask_head_channels, cfg.mask_head_channels, n)
    anchor_gen = AnchorGenerator(tuple((a,) for a in cfg.anchor_sizes), ((0.5, 1.0, 2.0),) * len(cfg.anchor_sizes))
    model = MaskRCNN(
        backbone,
        rpn_anchor_generator=anchor_gen,
        num_classes=None,
        min_size=cfg.min_size,
        max_size=cfg.max_size,
        rpn_pre_nms_top_n_train=cfg.rpn_pre_nms_train,
        rpn_post_nms_top_n_train=cfg.rpn_post_nms_train,
        rpn_pre_nms_top_n_test=cfg.rpn_pre_nms_test,
        rpn_post_nms_top_n_test=cfg.rpn_post_nms_test,
        rpn_batch_size_per_image=cfg.rpn_batch_size,
        box_batch_size_per_image=cfg.box_batch_size,
        box_detections_per_img=cfg.detections_per_img,
        box_score_thresh=cfg.score_thresh,
        box_head=box_head,
        box_predictor=box_predictor,
        mask_head=mask_head,
        mask_predictor=mask_predictor,
    )
    return model, init


def _resnet_body(cfg: SegConfig, weights, norm_layer) -> tuple[nn.Module, list[int], OrderedDict]:
    """A torchvision ResNet, its first ``cfg.trainable_layers`` stages from the deepest left trainable, and
    the channels and names of its four stages (strides 4 to 32) for the feature pyramid."""
    import torchvision

    resnet = getattr(torchvision.models, cfg.backbone)(weights=weights, norm_layer=norm_layer)
    layers_to_train = ["layer4", "layer3", "layer2", "layer1", "conv1"][: cfg.trainable_layers]
    if cfg.trainable_layers == 5:
        layers_to_train.append("bn1")
    for name, p in resnet.named_parameters():
        if not any(name.startswith(layer) for layer in layers_to_train):
            p.requires_grad_(False)
    stage2 = resnet.inplanes // 8
    in_channels = [stage2 * 2 ** (i - 1) for i in (1, 2, 3, 4)]
    return_layers = OrderedDict((f"layer{k}", str(v)) for v, k in enumerate((1, 2, 3, 4)))
    return resnet, in_channels, return_layers


def _mobilenet_body(cfg: SegConfig, weights, norm_layer) -> tuple[nn.Module, list[int], OrderedDict]:
    """torchvision's MobileNetV3 features, split into five stages (the stem and the blocks of strides 4, 8,
    16 and 32, where torchvision marks a block ``_is_cn``); the deepest ``cfg.trainable_layers`` stages are
    left trainable, and the last block of each of the four strided stages feeds the feature pyramid (the
    same strides as a ResNet's ``layer1`` to ``layer4``, so the anchors of a profile keep their meaning)."""
    import torchvision

    features = getattr(torchvision.models, cfg.backbone)(weights=weights, norm_layer=norm_layer).features
    starts = [i for i, block in enumerate(features) if getattr(block, "_is_cn", False)]
    if len(starts) != 4:  # torchvision's layout (strides 4, 8, 16, 32) changed under us
        raise ValueError(f"backbone: {cfg.backbone} has {len(starts)} strided stages, expected 4")
    first_trainable = ([0] + starts)[5 - cfg.trainable_layers] if cfg.trainable_layers else len(features)
    for block in features[:first_trainable]:
        for p in block.parameters():
            p.requires_grad_(False)
    ends = [s - 1 for s in starts[1:]] + [len(features) - 1]
    in_channels = [_out_channels(features[i]) for i in ends]
    return_layers = OrderedDict((str(i), str(v)) for v, i in enumerate(ends))
    return features, in_channels, return_layers


def _out_channels(block: nn.Module) -> int:
    """Output channels of a MobileNetV3 block (an inverted residual, or the last 1x1 conv-norm-activation)."""
    out = getattr(block, "out_channels", None)
    if isinstance(out, int):
        return out
    convs = [m for m in block.modules() if isinstance(m, nn.Conv2d)]
    return int(convs[-1].out_channels)


def set_train_sizes(model: nn.Module, cfg: SegConfig, training: bool) -> None:
    """Switch the model's resize between multi-scale training sizes and the fixed test size.

    torchvision draws the shorter side at random from ``transform.min_size`` in training mode and
    uses its last entry at evaluation, so the tuple is swapped rather than relying on that detail.
    """
    m = model.module if hasattr(model, "module") else model
    m.transform.min_size = tuple(cfg.train_min_sizes) if training else (cfg.min_size,)
