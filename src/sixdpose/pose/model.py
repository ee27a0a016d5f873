"""The networks of the learned stage (paper section IV-C, Fig. 5 and 6): PSPNet colour embedding,
DenseFusion-like point fusion with attention pooling, and the iterative refiner.

Shapes (``w`` = width multiplier, ``c(x) = max(1, round(x * w))``; ``w = 1`` is the paper):

* :class:`PSPNet`: image (B, 3, H, W) (H, W multiples of 8) -> embedding (B, emb_dim=32, H, W).
  ResNet-18 trunk (no pre-training) with layer3/layer4 dilated (2, 4; output stride 8), pyramid pooling
  (1, 2, 3, 6) to 1024 channels, three x2 up-sampling blocks 1024 -> 256 -> 64 -> 64 (3x3 conv + PReLU),
  1x1 conv to ``emb_dim``.
* :class:`PoseNet`: cloud (N, P, 3) metres + per-point embedding (N, emb_dim, P) -> per point
  geometry 3->64->128 and colour emb->64->128 (1x1 Conv1d + ReLU); [64+64] and [128+128] concatenated,
  then 256->512->1024, averaged over points into a global feature repeated to every point:
  128 + 256 + 1024 = 1408 per point. Rotation and translation heads 1408->640->256->128 each,
  attention pooling (Linear(128, 1) score per point, softmax over points, weighted sum), then a
  per-class linear output: rotation (quaternion 4 or 6D 6) and translation (3). The ``dense`` head
  (the project's own, :mod:`sixdpose.pose.dense`) replaces both heads by one 1408->640->256->128 per-point
  branch and a per-class 1x1 conv to 4 per point: object coordinates (offsets from the class's model-box
  centre in units of ``OFFSET_SCALE``, the cloud centred and in the same units) and a confidence logit,
  plus, with ``flips = F > 0``, F per-point logits of the class's shape flips (averaged over the points).
* :class:`Refiner`: object-frame cloud (N, P, 3) (fed in units of ``OFFSET_SCALE`` = 5 cm, its
  translation output in the same units: a change of units from the authors' metres, so that the
  point features are not swamped by the biases of a from-scratch network) + detached embedding (N, emb_dim, P): geometry
  3->64->128, embedding emb->64->128, [64+64] and [128+128] concatenated (384) -> 512 -> 1024,
  averaged; heads 1024->512->128 -> per-class quaternion and translation.

With ``input_frame = "pca"`` (dense head) the centred cloud is turned into its principal axes
(:func:`pca_frame`) before the point and local-shape branches see it.

``norm`` = ``none`` uses no normalisation layer anywhere (the paper); ``group``/``batch`` put one after
every convolution of the CNN and the point branches (an ablation).
"""

from __future__ import annotations

import math

import torch
import torch.nn as nn
import torch.nn.functional as F

from .geometry import quaternion_to_matrix, rotation_dim, rotation_from_output

#: Length unit (metres) of the centred cloud and of the predicted offset in ``centroid_offset`` mode.
OFFSET_SCALE = 0.05


def _ch(x: int, width: float) -> int:
    return max(1, int(round(x * width)))


def norm2d(kind: str, ch: int) -> nn.Module:
    """A 2D normalisation layer of ``kind`` (none | group | batch) for ``ch`` channels."""
    if kind == "none":
        return nn.Identity()
    if kind == "group":
        return nn.GroupNorm(math.gcd(ch, 8), ch)
    if kind == "batch":
        return nn.BatchNorm2d(ch)
    raise ValueError(f"unknown norm {kind!r}")


def norm1d(kind: str, ch: int) -> nn.Module:
    """A normalisation layer for (N, C, P) point features (none | group | batch)."""
    if kind == "none":
        return nn.Identity()
    if kind == "group":
        return nn.GroupNorm(math.gcd(ch, 8), ch)
    if kind == "batch":
        return nn.BatchNorm1d(ch)
    raise ValueError(f"unknown norm {kind!r}")


class BasicBlock(nn.Module):
    """ResNet basic block (two 3x3 convs) with optional dilation and normalisation."""

    def __init__(self, cin: int, cout: int, stride: int = 1, dilation: int = 1, norm: str = "none"):
        super().__init__()
        self.conv1 = nn.Conv2d(cin, cout, 3, stride, padding=dilation, dilation=dilation, bias=norm == "none")
        self.bn1 = norm2d(norm, cout)
        self.conv2 = nn.Conv2d(cout, cout, 3, 1, padding=dilation, dilation=dilation, bias=norm == "none")
        self.bn2 = norm2d(norm, cout)
        self.down = None
        if stride != 1 or cin != cout:
            self.down = nn.Sequential(nn.Conv2d(cin, cout, 1, stride, bias=norm == "none"), norm2d(norm, cout))

    def forward(self, x):  # noqa: D102
        y = F.relu(self.bn1(self.conv1(x)))
        y = self.bn2(self.conv2(y))
        return F.relu(y + (x if self.down is None else self.down(x)))


class ResNet18(nn.Module):
    """ResNet-18 trunk, layer3/layer4 dilated (output stride 8); (B, 3, H, W) -> (B, c(512), H/8, W/8)."""

    def __init__(self, width: float = 1.0, norm: str = "none"):
        super().__init__()
        c = [_ch(v, width) for v in (64, 128, 256, 512)]
        self.stem = nn.Sequential(nn.Conv2d(3, c[0], 7, 2, 3, bias=norm == "none"), norm2d(norm, c[0]),
                                  nn.ReLU(inplace=True), nn.MaxPool2d(3, 2, 1))
        self.layer1 = nn.Sequential(BasicBlock(c[0], c[0], norm=norm), BasicBlock(c[0], c[0], norm=norm))
        self.layer2 = nn.Sequential(BasicBlock(c[0], c[1], 2, norm=norm), BasicBlock(c[1], c[1], norm=norm))
        self.layer3 = nn.Sequential(BasicBlock(c[1], c[2], 1, 2, norm), BasicBlock(c[2], c[2], 1, 2, norm))
        self.layer4 = nn.Sequential(BasicBlock(c[2], c[3], 1, 4, norm), BasicBlock(c[3], c[3], 1, 4, norm))
        self.out_channels = c[3]

    def forward(self, x):  # noqa: D102
        return self.layer4(self.layer3(self.layer2(self.layer1(self.stem(x)))))


class PSPModule(nn.Module):
    """Pyramid pooling (bins 1, 2, 3, 6; a 1x1 conv per bin as DenseFusion), bottleneck to ``cout`` + ReLU."""

    def __init__(self, cin: int, cout: int, sizes=(1, 2, 3, 6), norm: str = "none"):
        super().__init__()
        self.sizes = tuple(sizes)
        self.stages = nn.ModuleList([nn.Conv2d(cin, cin, 1, bias=False) for _ in sizes])
        self.bottleneck = nn.Conv2d(cin * (len(sizes) + 1), cout, 1)
        self.norm = norm2d(norm, cout)

    def forward(self, x):  # noqa: D102
        h, w = x.shape[-2:]
        pri = [F.interpolate(conv(F.adaptive_avg_pool2d(x, s)), size=(h, w), mode="bilinear", align_corners=False)
               for s, conv in zip(self.sizes, self.stages, strict=True)]
        return F.relu(self.norm(self.bottleneck(torch.cat(pri + [x], 1))))


class PSPUpsample(nn.Module):
    """x2 bilinear up-sampling, 3x3 conv, PReLU."""

    def __init__(self, cin: int, cout: int, norm: str = "none"):
        super().__init__()
        self.conv = nn.Conv2d(cin, cout, 3, padding=1)
        self.norm = norm2d(norm, cout)
        self.act = nn.PReLU()

    def forward(self, x):  # noqa: D102
        x = F.interpolate(x, scale_factor=2, mode="bilinear", align_corners=False)
        return self.act(self.norm(self.conv(x)))


class PSPNet(nn.Module):
    """Per-pixel colour embedding: (B, 3, H, W) normalised image -> (B, emb_dim, H, W); H, W multiples of 8."""

    def __init__(self, width: float = 1.0, emb_dim: int = 32, norm: str = "none"):
        super().__init__()
        self.feats = ResNet18(width, norm)
        c1024, c256, c64 = _ch(1024, width), _ch(256, width), _ch(64, width)
        self.psp = PSPModule(self.feats.out_channels, c1024, norm=norm)
        self.up1 = PSPUpsample(c1024, c256, norm)
        self.up2 = PSPUpsample(c256, c64, norm)
        self.up3 = PSPUpsample(c64, c64, norm)
        self.final = nn.Conv2d(c64, emb_dim, 1)

    def forward(self, x):  # noqa: D102
        return self.final(self.up3(self.up2(self.up1(self.psp(self.feats(x))))))


def _conv1d(cin, cout, norm):
    return nn.Sequential(nn.Conv1d(cin, cout, 1), norm1d(norm, cout), nn.ReLU(inplace=True))


class AttentionPool(nn.Module):
    """Attention pooling over points: score = Linear(C, 1) per point, softmax over points, weighted sum.

    forward(x (N, C, P)) -> (pooled (N, C), weights (N, P) summing to 1 over P).
    """

    def __init__(self, ch: int):
        super().__init__()
        self.score = nn.Linear(ch, 1)

    def forward(self, x):  # noqa: D102
        w = torch.softmax(self.score(x.transpose(1, 2))[..., 0], dim=1)
        return torch.einsum("ncp,np->nc", x, w), w


def gather_points(maps: torch.Tensor, img_index: torch.Tensor, choose: torch.Tensor) -> torch.Tensor:
    """Per-pixel maps at the sampled pixels: (B, C, H, W) maps (CNN features or the images themselves),
    (N,) long image of each instance, (N, P) long flat pixel indices -> (N, C, P)."""
    flat = maps.flatten(2)[img_index]  # (N, C, HW)
    return torch.gather(flat, 2, choose[:, None, :].expand(-1, flat.shape[1], -1))


def standardise_colours(colours: torch.Tensor, eps: float = 1e-3) -> torch.Tensor:
    """Per-instance standardised point colours: (N, 3, P) -> (N, 3, P), each instance's mean colour removed
    and divided by one spread over its three channels, so a brighter or dimmer exposure (a real camera's
    against the renderer's) gives the same input while the contrast between channels (the hue) is kept."""
    c = colours - colours.mean(dim=2, keepdim=True)
    return c / (c.pow(2).mean(dim=(1, 2), keepdim=True).sqrt() + eps)


class LocalGeometry(nn.Module):
    """Per-point embedding of the local shape around each point (``appearance="local"``): two EdgeConv
    layers (Wang et al. 2019, DGCNN) over the ``k`` nearest neighbours of every point in the sampled cloud,
    ``max_j h([f_i, f_j - f_i])``, the second on the first's features. Unlike a plain PointNet, whose
    per-point features know only where a point is, these tell a box's corner from its edge and face, so the
    dense head can find correspondences without a global rotation.

    With ``colour=True`` (``appearance="local_rgb"``) each point also carries its pixel's colour, standardised
    per instance (:func:`standardise_colours`), and the first layer sees ``[c_i, c_j - c_i]`` beside the
    geometry: the local texture pattern (a letter's edge, a label's border) without a CNN over the image.

    Args: emb_dim (output channels), k (neighbours), width, norm as in :class:`PoseNet`; colour.
    Input (N, P, 3) centred cloud in units of ``OFFSET_SCALE`` (and (N, 3, P) colours with ``colour``);
    output (N, emb_dim, P).
    """

    def __init__(self, emb_dim: int, k: int = 16, width: float = 1.0, norm: str = "none", colour: bool = False):
        super().__init__()
        self.k, self.colour = k, colour
        c = _ch(64, width)
        self.edge1 = nn.Sequential(nn.Conv2d(12 if colour else 6, c, 1), norm2d(norm, c), nn.ReLU(inplace=True),
                                   nn.Conv2d(c, c, 1), norm2d(norm, c), nn.ReLU(inplace=True))
        self.edge2 = nn.Sequential(nn.Conv2d(2 * c, c, 1), norm2d(norm, c), nn.ReLU(inplace=True))
        self.out = nn.Conv1d(2 * c, emb_dim, 1)

    @staticmethod
    def _edges(f: torch.Tensor, idx: torch.Tensor, scale: float = 1.0) -> torch.Tensor:
        """(N, C, P) features and (N, P, k) neighbour indices -> (N, 2C, P, k) ``[f_i, scale (f_j - f_i)]``."""
        ft = f.transpose(1, 2)  # (N, P, C)
        nb = ft[torch.arange(len(f), device=f.device)[:, None, None], idx].permute(0, 3, 1, 2)  # (N, C, P, k)
        fi = f[:, :, :, None].expand_as(nb)
        return torch.cat([fi, scale * (nb - fi)], dim=1)

    @staticmethod
    def _edge_conv(conv: nn.Module, parts: list[tuple[torch.Tensor, float]], idx: torch.Tensor) -> torch.Tensor:
        """``conv(cat([_edges(f, idx, scale) for f, scale in parts]))`` without building the (N, 2C, P, k) edge
        tensor: a 1x1 convolution is linear, so each part's ``W_i f_i + W_j scale (f_j - f_i)`` is
        ``(W_i - scale W_j) f`` at point i plus ``scale W_j f`` gathered at its neighbour j: two products per
        point, not per edge (the same function). parts: (N, C, P) features and their offset scales; idx: (N, P,
        k) neighbour indices. Returns (N, out, P, k)."""
        assert isinstance(conv, nn.Conv2d)
        w, col = conv.weight[:, :, 0, 0], 0
        heres, theres = [], []
        for f, scale in parts:
            c = f.shape[1]
            wi, wj = w[:, col:col + c], w[:, col + c:col + 2 * c]
            col += 2 * c
            heres.append((wi - scale * wj) @ f)  # (N, out, P)
            theres.append((scale * wj) @ f)
        assert col == w.shape[1]
        here, there = sum(heres[1:], heres[0]), sum(theres[1:], theres[0])
        if conv.bias is not None:
            here = here + conv.bias[:, None]
        nb = there.transpose(1, 2)[torch.arange(len(idx), device=idx.device)[:, None, None], idx]  # (N, P, k, out)
        return here[:, :, :, None] + nb.permute(0, 3, 1, 2)

    def forward(self, cloud: torch.Tensor, colours: torch.Tensor | None = None) -> torch.Tensor:  # noqa: D102
        x = cloud.transpose(1, 2)  # (N, 3, P)
        k = min(self.k, cloud.shape[1])
        idx = torch.cdist(cloud, cloud).topk(k, dim=2, largest=False).indices  # (N, P, k), self included
        # neighbour offsets are millimetres to centimetres: x5 brings them to the centred cloud's scale
        parts = [(x, 5.0)]
        if self.colour:
            if colours is None:
                raise ValueError("LocalGeometry(colour=True) needs the points' colours")
            parts.append((colours, 1.0))
        f1 = self.edge1[1:](self._edge_conv(self.edge1[0], parts, idx)).max(dim=3).values
        f2 = self.edge2[1:](self._edge_conv(self.edge2[0], [(f1, 1.0)], idx)).max(dim=3).values
        return self.out(torch.cat([f1, f2], dim=1))


def pca_frame(centred: torch.Tensor, centroid: torch.Tensor) -> torch.Tensor:
    """The principal axes of each instance's centred cloud, as a right-handed frame with fixed signs.

    Columns: ``v1`` the axis of largest spread (its sign: the cloud's third moment along it positive),
    ``v3`` the axis of least spread (for a surface seen from one side, about its normal: its sign towards
    the camera, ``v3 . -centroid >= 0``) and ``v2 = v3 x v1``. Turning the cloud and its centroid together
    about the camera centre turns the frame with them, so ``centred @ V`` is unchanged (up to the signs'
    ties: a spread equal along two axes, or a third moment near 0). No gradient flows through it.

    Args:
        centred: (N, P, 3) points minus their centroid (any length unit). centroid: (N, 3) camera frame.
    Returns:
        (N, 3, 3) float32 rotations whose columns are ``v1, v2, v3`` in the camera frame.
    """
    with torch.no_grad(), torch.autocast(centred.device.type, enabled=False):
        x = centred.float()
        cov = x.transpose(1, 2) @ x / max(x.shape[1], 1)
        # ascending eigenvalues; a batch of 3x3 matrices is decomposed on the CPU (on a GPU the solver's launch
        # and synchronisation cost more than the work: about a millisecond per batch on an H200)
        _, vec = torch.linalg.eigh(cov.cpu()) if cov.is_cuda else torch.linalg.eigh(cov)
        vec = vec.to(cov.device)
        v1, v3 = vec[..., 2], vec[..., 0]
        s1 = torch.sign(((x @ v1[..., None]) ** 3).sum(dim=(1, 2)))
        v1 = v1 * torch.where(s1 == 0, torch.ones_like(s1), s1)[:, None]
        s3 = torch.sign(-(v3 * centroid.float()).sum(dim=1))
        v3 = v3 * torch.where(s3 == 0, torch.ones_like(s3), s3)[:, None]
        return torch.stack([v1, torch.linalg.cross(v3, v1), v3], dim=2)


class PoseNet(nn.Module):
    """The main network (see the module docstring).

    Args:
        num_classes: object classes (the per-class outputs). width, emb_dim, norm: as in
            :class:`~sixdpose.pose.config.PoseConfig`. rotation: ``quaternion`` | ``6d``.
            translation: ``absolute`` | ``centroid_offset``. head: ``paper`` (the rotation and translation
            heads) or ``dense`` (per-point object coordinates and confidences, :mod:`sixdpose.pose.dense`;
            ``rotation`` and ``translation`` are then unused). flips: room for each class's shape flips
            (dense head). appearance: ``cnn`` (per-pixel CNN embeddings), ``local`` (no CNN: the
            :class:`LocalGeometry` embedding), ``local_rgb`` (the same with each point's colour) or ``none``
            (no CNN, a zero embedding: the points alone). input_frame: ``camera`` or ``pca`` (dense head:
            the centred cloud turned into its principal axes, :func:`pca_frame`).
    """

    flip_R: torch.Tensor
    flip_t: torch.Tensor
    flip_n: torch.Tensor

    def __init__(self, num_classes: int, width: float = 1.0, emb_dim: int = 32, norm: str = "none",
                 rotation: str = "quaternion", translation: str = "absolute", head: str = "paper", flips: int = 0,
                 appearance: str = "cnn", input_frame: str = "camera"):
        super().__init__()
        self.input_frame = input_frame if head == "dense" else "camera"
        self.num_classes, self.rotation, self.translation, self.head = num_classes, rotation, translation, head
        self.flips = flips if head == "dense" else 0
        self.emb_dim, self.appearance = emb_dim, appearance
        # appearance "none": geometry alone, no CNN (the embedding is zeros, see embed); "local": no CNN, the
        # embedding is the local shape around each point (LocalGeometry); "local_rgb": that with point colours
        self.cnn = PSPNet(width, emb_dim, norm) if appearance == "cnn" else None
        self.local = (LocalGeometry(emb_dim, width=width, norm=norm, colour=appearance == "local_rgb")
                      if appearance in ("local", "local_rgb") else None)
        c = lambda x: _ch(x, width)  # noqa: E731
        self.conv1, self.conv2 = _conv1d(3, c(64), norm), _conv1d(c(64), c(128), norm)
        self.e_conv1, self.e_conv2 = _conv1d(emb_dim, c(64), norm), _conv1d(c(64), c(128), norm)
        self.conv5, self.conv6 = _conv1d(2 * c(128), c(512), norm), _conv1d(c(512), c(1024), norm)
        self.fused_channels = 2 * c(64) + 2 * c(128) + c(1024)

        def make_head():
            return nn.Sequential(_conv1d(self.fused_channels, c(640), norm), _conv1d(c(640), c(256), norm),
                                 _conv1d(c(256), c(128), norm))

        if self.head == "dense":  # per point: object coordinates (3) and a confidence logit, per class
            self.head_d = make_head()
            self.out_d = nn.Conv1d(c(128), num_classes * (4 + self.flips), 1)
            if self.flips:  # each class's shape flips (set_flips): (C, F, 3, 3), (C, F, 3) metres, (C,) count
                self.register_buffer("flip_R", torch.eye(3).repeat(num_classes, self.flips, 1, 1))
                self.register_buffer("flip_t", torch.zeros(num_classes, self.flips, 3))
                self.register_buffer("flip_n", torch.ones(num_classes, dtype=torch.long))
        else:
            self.head_r, self.head_t = make_head(), make_head()
            self.att_r, self.att_t = AttentionPool(c(128)), AttentionPool(c(128))
            self.out_r = nn.Linear(c(128), num_classes * rotation_dim(rotation))
            self.out_t = nn.Linear(c(128), num_classes * 3)
        # (num_classes, 3) metres: each class's model-box centre in its object frame (set_centres); the
        # centroid_offset mode predicts where this centre is, so the translation does not hinge on the
        # rotation when a model's origin lies off its body (YCB origins are up to 12 cm off)
        self.register_buffer("centres", torch.zeros(num_classes, 3))
        # (num_classes,) training instances seen per class (counted by the training task; -1: unknown, a
        # network built outside training or a checkpoint from before the count): inference skips classes at 0
        self.register_buffer("seen", torch.full((num_classes,), -1.0))

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        if prefix + "seen" not in state_dict:  # a checkpoint from before the count: unknown
            state_dict[prefix + "seen"] = torch.full_like(self.seen, -1.0)
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    def set_centres(self, centres) -> None:
        """Set the per-class model-box centres, (num_classes, 3) metres in the object frames (saved in the state)."""
        self.centres.copy_(torch.as_tensor(centres, dtype=self.centres.dtype))

    def set_flips(self, flips: dict[int, tuple]) -> None:
        """Set the classes' shape flips: ``{class index: (R (K, 3, 3), t (K, 3) metres)}``, the identity first,
        ``K <= flips`` (classes not given keep the identity alone); saved in the state."""
        for k, (R, t) in flips.items():
            R, t = torch.as_tensor(R, dtype=torch.float32), torch.as_tensor(t, dtype=torch.float32)
            if not 1 <= len(R) <= self.flips:
                raise ValueError(f"class {k}: {len(R)} flips, the network has room for 1 to {self.flips}")
            self.flip_R[k, : len(R)] = R
            self.flip_t[k, : len(R)] = t
            self.flip_n[k] = len(R)

    @property
    def reads_images(self) -> bool:
        """Whether :meth:`forward` reads its ``images`` (a CNN, or local geometry with the points' colours);
        ``appearance`` "local" and "none" read the points alone."""
        return self.cnn is not None or (self.local is not None and self.local.colour)

    def embed(self, images: torch.Tensor, img_index: torch.Tensor, choose: torch.Tensor) -> torch.Tensor:
        """Per-point colour embeddings: one CNN pass over ``images``, gathered at the sampled pixels.

        Args:
            images: (B, 3, H, W) normalised images (full images or crops).
            img_index: (N,) long, the image of each instance. choose: (N, P) long flat pixel indices.
        Returns:
            (N, emb_dim, P); zeros without a CNN (``appearance="none"``: the images are not read).
        """
        if self.cnn is None:
            return torch.zeros(choose.shape[0], self.emb_dim, choose.shape[1], device=choose.device,
                               dtype=torch.float32)
        return gather_points(self.cnn(images), img_index, choose)

    def fuse(self, cloud: torch.Tensor, emb: torch.Tensor) -> torch.Tensor:
        """Dense fusion: cloud (N, P, 3) and embedding (N, E, P) -> (N, 1408*w, P) per-point features."""
        pf, g = self._fused(cloud, emb)
        return torch.cat([pf, g[:, :, None].expand(-1, -1, pf.shape[2])], 1)

    def _fused(self, cloud: torch.Tensor, emb: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`fuse`'s two parts: the per-point features (N, 384*w, P) and the global feature (N, 1024*w),
        which :meth:`fuse` repeats at every point."""
        x = cloud.transpose(1, 2)
        x1, e1 = self.conv1(x), self.e_conv1(emb)
        x2, e2 = self.conv2(x1), self.e_conv2(e1)
        pf2 = torch.cat([x2, e2], 1)
        g = self.conv6(self.conv5(pf2)).mean(dim=2)
        return torch.cat([x1, e1, pf2], 1), g

    @staticmethod
    def _head(head: nn.Sequential, pf: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
        """``head(fuse(...))`` from :meth:`_fused`'s parts without repeating the global feature: the first 1x1
        convolution's product with ``g`` is the same at every point, so it is computed once per instance and
        added (the same function; a third of the head's multiplications saved)."""
        first = head[0]  # _conv1d: Conv1d, norm, ReLU
        assert isinstance(first, nn.Sequential) and isinstance(first[0], nn.Conv1d)
        w, cp = first[0].weight, pf.shape[1]
        y = F.conv1d(pf, w[:, :cp]) + F.linear(g, w[:, cp:, 0], first[0].bias)[:, :, None]
        return head[1:](first[1:](y))

    def forward(self, images, img_index, choose, cloud, obj_index):
        """Predict poses.

        Args:
            images: (B, 3, H, W). img_index: (N,) long. choose: (N, P) long. cloud: (N, P, 3) camera-frame
                points, metres. obj_index: (N,) long class indices.
        Returns:
            dict: ``R`` (N, 3, 3), ``t`` (N, 3) metres (``X_CO``), ``emb`` (N, E, P) colour embeddings,
            ``att_r``/``att_t`` (N, P) attention weights. The dense head instead: ``coords`` (N, P, 3)
            object coordinates of the points (metres), ``conf_logit`` (N, P) and ``emb``; with flips also
            ``flip_logit`` (N, F), the logits of the class's flips, -inf past its count; with
            ``input_frame = "pca"`` also ``frame`` (N, 3, 3), the :func:`pca_frame` the cloud was seen in.
        """
        centroid = cloud.mean(dim=1)
        centred = (cloud - centroid[:, None, :]) / OFFSET_SCALE
        frame = None
        if self.input_frame == "pca":  # the cloud in its own principal axes (the object coordinates do not turn)
            frame = pca_frame(centred, centroid)
            centred = centred @ frame.to(centred.dtype)
        if self.local is not None:
            colours = None
            if self.local.colour:  # the sampled pixels' colours, gathered from the (normalised) crops
                colours = standardise_colours(gather_points(images, img_index, choose))
            emb = self.local(centred, colours)
        else:
            emb = self.embed(images, img_index, choose)
        if self.head == "dense":
            out = self._dense(centred, emb, obj_index)
            if frame is not None:
                out["frame"] = frame
            return out
        # centroid_offset: the centred cloud in units of OFFSET_SCALE (spread ~1, not ~0.05 m, so the
        # geometry features are not swamped by the biases) and the offset predicted in the same units
        inp = (cloud - centroid[:, None, :]) / OFFSET_SCALE if self.translation == "centroid_offset" else cloud
        pf, g = self._fused(inp, emb)
        hr, wr = self.att_r(self._head(self.head_r, pf, g))
        ht, wt = self.att_t(self._head(self.head_t, pf, g))
        n = len(obj_index)
        rd = rotation_dim(self.rotation)
        r = self.out_r(hr).view(n, self.num_classes, rd)[torch.arange(n), obj_index]
        t = self.out_t(ht).view(n, self.num_classes, 3)[torch.arange(n), obj_index]
        if self.rotation == "quaternion":
            r = r + torch.tensor([1.0, 0, 0, 0], device=r.device, dtype=r.dtype)  # identity at zero output
        R = rotation_from_output(r, self.rotation)
        if self.translation == "centroid_offset":  # t_c = centroid + offset is the model-box centre
            t = centroid + OFFSET_SCALE * t - torch.einsum("nij,nj->ni", R, self.centres[obj_index].to(R.dtype))
        return {"R": R, "t": t, "emb": emb, "att_r": wr, "att_t": wt}

    def _dense(self, centred, emb, obj_index):
        """The dense head: the centred cloud (N, P, 3) in units of OFFSET_SCALE (in the input frame), per-point
        object coordinates as offsets (same units) from the class's model-box centre, and a confidence logit."""
        h = self._head(self.head_d, *self._fused(centred, emb))  # (N, 128*w, P)
        # out_d for each instance's own class only (its rows of the weight): the other classes' outputs unused
        k = 4 + self.flips
        o = torch.baddbmm(self.out_d.bias.view(self.num_classes, k)[obj_index][:, :, None],
                          self.out_d.weight.view(self.num_classes, k, -1)[obj_index], h)  # (N, 4 + F, P)
        coords = self.centres[obj_index].to(o.dtype)[:, None, :] + OFFSET_SCALE * o[:, :3].transpose(1, 2)
        out = {"coords": coords, "conf_logit": o[:, 3], "emb": emb}
        if self.flips:
            logit = o[:, 4:].mean(dim=2)  # (N, F)
            room = torch.arange(self.flips, device=o.device)[None] < self.flip_n[obj_index][:, None]
            out["flip_logit"] = logit.masked_fill(~room, float("-inf"))
        return out


class Refiner(nn.Module):
    """The iterative refiner (see the module docstring): one correction per call.

    forward(cloud_O (N, P, 3) object-frame points, emb (N, E, P), obj_index (N,)) ->
    ``(R_r (N, 3, 3), t_r (N, 3))``, the residual pose to compose with
    :func:`~sixdpose.pose.geometry.compose_refinement`.
    """

    def __init__(self, num_classes: int, width: float = 1.0, emb_dim: int = 32):
        super().__init__()
        self.num_classes = num_classes
        c = lambda x: _ch(x, width)  # noqa: E731
        self.conv1, self.conv2 = _conv1d(3, c(64), "none"), _conv1d(c(64), c(128), "none")
        self.e_conv1, self.e_conv2 = _conv1d(emb_dim, c(64), "none"), _conv1d(c(64), c(128), "none")
        self.conv5, self.conv6 = _conv1d(2 * c(64) + 2 * c(128), c(512), "none"), _conv1d(c(512), c(1024), "none")
        self.head_r = nn.Sequential(nn.Linear(c(1024), c(512)), nn.ReLU(inplace=True), nn.Linear(c(512), c(128)),
                                    nn.ReLU(inplace=True), nn.Linear(c(128), num_classes * 4))
        self.head_t = nn.Sequential(nn.Linear(c(1024), c(512)), nn.ReLU(inplace=True), nn.Linear(c(512), c(128)),
                                    nn.ReLU(inplace=True), nn.Linear(c(128), num_classes * 3))

    def forward(self, cloud_O, emb, obj_index):  # noqa: D102
        x = cloud_O.transpose(1, 2) / OFFSET_SCALE  # object-frame cloud in units of OFFSET_SCALE (spread ~1)
        x1, e1 = self.conv1(x), self.e_conv1(emb)
        x2, e2 = self.conv2(x1), self.e_conv2(e1)
        pf = torch.cat([x1, e1, x2, e2], 1)
        g = self.conv6(self.conv5(pf)).mean(dim=2)
        n = len(obj_index)
        q = self.head_r(g).view(n, self.num_classes, 4)[torch.arange(n), obj_index]
        q = q + torch.tensor([1.0, 0, 0, 0], device=q.device, dtype=q.dtype)
        t = OFFSET_SCALE * self.head_t(g).view(n, self.num_classes, 3)[torch.arange(n), obj_index]
        return quaternion_to_matrix(q), t


def build_posenet(cfg, num_classes: int) -> PoseNet:
    """The :class:`PoseNet` of a :class:`~sixdpose.pose.config.PoseConfig`."""
    return PoseNet(num_classes, cfg.width, cfg.emb_dim, cfg.norm, cfg.rotation, cfg.translation,
                   getattr(cfg, "head", "paper"), getattr(cfg, "flips", 0), getattr(cfg, "appearance", "cnn"),
                   getattr(cfg, "input_frame", "camera"))


def build_refiner(cfg, num_classes: int, emb_dim: int) -> Refiner:
    """The :class:`Refiner` of a :class:`~sixdpose.pose.config.RefinerConfig`."""
    return Refiner(num_classes, cfg.width, emb_dim)
