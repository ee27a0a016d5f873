"""Helpers for the registration / evaluation / BOP tests (no tests here).

* :func:`make_shape`: an asymmetric test object (three boxes of different sizes), surface samples with
  outward normals and colours, metres.
* :func:`render_depth`: z-buffer splatting of object point clouds into a small depth image.
* :func:`write_synthetic_dataset`: a tiny dataset in the synthetic layout (``datasets/synthetic.py``)
  built by hand, for tests that must not wait for the generator.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

SHARED = Path(os.environ.get("SIXDPOSE_SHARED", Path(__file__).parents[1].parent / "shared"))
YCBV = SHARED / "data" / "ycbv_sample"
LMO = SHARED / "data" / "lmo"

K_SMALL = np.array([[150.0, 0, 79.5], [0, 150.0, 59.5], [0, 0, 1]])
H_SMALL, W_SMALL = 120, 160


def _box_surface(lo, hi, spacing, rng):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    pts, nrm = [], []
    for ax in range(3):
        o = [i for i in range(3) if i != ax]
        for side, val in ((-1, lo[ax]), (1, hi[ax])):
            area = (hi[o[0]] - lo[o[0]]) * (hi[o[1]] - lo[o[1]])
            n = max(int(area / spacing**2), 4)
            p = np.empty((n, 3))
            p[:, ax] = val
            p[:, o[0]] = rng.uniform(lo[o[0]], hi[o[0]], n)
            p[:, o[1]] = rng.uniform(lo[o[1]], hi[o[1]], n)
            q = np.zeros((n, 3))
            q[:, ax] = side
            pts.append(p)
            nrm.append(q)
    return np.concatenate(pts), np.concatenate(nrm)


def make_shape(spacing: float = 0.002, seed: int = 0):
    """Asymmetric object (~15 cm): a base slab, an off-centre tower and a side arm.

    Returns:
        points (N, 3), normals (N, 3), colours (N, 3) in [0, 1], diameter (m).
    """
    rng = np.random.default_rng(seed)
    boxes = [
        ((-0.06, -0.04, 0.0), (0.06, 0.04, 0.02)),
        ((0.02, -0.04, 0.02), (0.06, 0.0, 0.09)),
        ((-0.06, 0.04, 0.0), (-0.02, 0.07, 0.04)),
    ]
    P, N = [], []
    for lo, hi in boxes:
        p, n = _box_surface(lo, hi, spacing, rng)
        # drop samples inside another box (shared faces)
        inside = np.zeros(len(p), bool)
        for lo2, hi2 in boxes:
            if (lo2, hi2) == (lo, hi):
                continue
            inside |= np.all((p >= np.asarray(lo2) - 1e-9) & (p <= np.asarray(hi2) + 1e-9), axis=1)
        P.append(p[~inside])
        N.append(n[~inside])
    P, N = np.concatenate(P), np.concatenate(N)
    P -= P.mean(axis=0)
    C = np.clip(0.5 + 3.0 * P, 0, 1)
    from scipy.spatial.distance import pdist

    sub = P[rng.choice(len(P), min(len(P), 1500), replace=False)]
    diam = float(pdist(sub).max())
    return P, N, C, diam


def render_depth(objects, K=K_SMALL, H=H_SMALL, W=W_SMALL):
    """Z-buffer splat of posed objects.

    Args:
        objects: list of (points (N, 3) object frame, normals (N, 3), R (3, 3), t (3,)).
    Returns:
        depth (H, W) float32 metres (0 = background), label (H, W) int (index into ``objects``, -1 bg).
    """
    depth = np.full(H * W, np.inf)
    label = np.full(H * W, -1)
    for k, (pts, nrm, R, t) in enumerate(objects):
        pc = pts @ R.T + t
        nc = nrm @ R.T
        front = np.einsum("ij,ij->i", nc, -pc) > 0
        pc = pc[front]
        u = np.round(K[0, 0] * pc[:, 0] / pc[:, 2] + K[0, 2]).astype(int)
        v = np.round(K[1, 1] * pc[:, 1] / pc[:, 2] + K[1, 2]).astype(int)
        ok = (u >= 0) & (u < W) & (v >= 0) & (v < H)
        idx = v[ok] * W + u[ok]
        z = pc[ok, 2]
        prev = depth.copy()
        np.minimum.at(depth, idx, z)
        label[depth < prev] = k
    depth[~np.isfinite(depth)] = 0
    return depth.reshape(H, W).astype(np.float32), label.reshape(H, W)


def look_pose(seed: int, t=(0.0, 0.0, 0.55)):
    """A random object rotation at translation ``t`` (metres)."""
    from scipy.spatial.transform import Rotation

    return Rotation.random(random_state=seed).as_matrix(), np.asarray(t, float)


def write_synthetic_dataset(root: Path, n_images: int = 3, two_instances_in_first: bool = True, seed: int = 0) -> Path:
    """Write a tiny dataset in the synthetic layout: one asymmetric object (``035_power_drill``,
    obj_id 15), 2 scenes, ``n_images`` images of 160x120, the first with two instances."""
    from sixdpose.datasets.layout import write_dataset

    name, oid = "035_power_drill", 15
    P, N, C, diam = make_shape(0.002, seed)
    Pd, Nd, _, _ = make_shape(0.0012, seed + 1)  # denser samples for rendering
    images = []
    for im in range(n_images):
        poses = [look_pose(seed * 100 + im, (0.0, 0.0, 0.55))]
        if im == 0 and two_instances_in_first:
            poses = [look_pose(seed * 100 + 50, (-0.09, 0.0, 0.6)), look_pose(seed * 100 + 51, (0.09, 0.02, 0.6))]
        depth, label = render_depth([(Pd, Nd, R, t) for R, t in poses])
        rgb = np.zeros((H_SMALL, W_SMALL, 3), np.uint8)
        rgb[label >= 0] = (200, 120, 40)
        insts = [{"obj_name": name, "obj_id": oid, "inst": k, "R": R, "t": t, "mask": label == k}
                 for k, (R, t) in enumerate(poses)]
        images.append({"im_id": im, "scene_id": im % 2, "K": K_SMALL, "rgb": rgb, "depth": depth, "instances": insts})
    models = {name: {"obj_id": oid, "diameter": diam, "symmetric": False, "points": P, "normals": N, "colors": C}}
    root = write_dataset(root, images, models, {"generator": "tests.test_reg_helpers"})
    return root


def results_without_time(path: Path) -> list[str]:
    """The results CSV's lines without the last column (``time``): two runs' estimates, times aside."""
    return [line.rsplit(",", 1)[0] for line in Path(path).read_text().splitlines()]
