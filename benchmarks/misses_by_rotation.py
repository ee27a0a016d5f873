"""Diagnosis of one object's misses in a results CSV on a synthetic split: the rotation error of each missed
and each correct instance, and how much dark print of the model the view shows.

For every GT instance of ``--obj`` with at least ``--min-px`` visible pixels, the estimate of its image
nearest to it in translation is compared with it: ADD below 0.1 x the diameter (correct) or not (a miss),
the angle of ``R_est R_gt^T`` in degrees, and the share of the model points visible under the GT pose (inside
the instance's mask, within ``--tol`` metres of the observed depth) whose colour is dark (every channel
below ``--dark``: black print, not the red seams). Prints the medians of both groups and the sorted values.

    python benchmarks/misses_by_rotation.py --data data/test --results runs/verify_test/super4pcs_icp_verify_nsd.csv \\
        --obj 1
"""

from __future__ import annotations

import argparse

import numpy as np

from sixdpose.artifacts.poses import read_results
from sixdpose.datasets.readers import open_dataset


def main() -> None:
    """Print the misses' and the correct instances' rotation errors and visible dark shares."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default="data/test")
    ap.add_argument("--results", required=True)
    ap.add_argument("--obj", type=int, required=True, help="obj_id")
    ap.add_argument("--min-px", type=int, default=400)
    ap.add_argument("--dark", type=float, default=0.3, help="a model colour is dark when every channel is below this")
    ap.add_argument("--tol", type=float, default=0.004, help="visibility: metres from the observed depth")
    a = ap.parse_args()
    ds = open_dataset(a.data)
    by_img: dict = {}
    for r in read_results(a.results):
        if r.obj_id == a.obj:
            by_img.setdefault((r.scene_id, r.im_id), []).append(r)
    model = ds.model(a.obj)
    P, d = model.points, model.diameter
    if model.colors is None:
        raise SystemExit(f"{a.data}: model {a.obj} has no colours")
    dark = model.colors.max(axis=1) < a.dark
    out = []
    for i, key in enumerate(ds.keys()):
        if key not in by_img:
            continue
        s = ds[i]
        for g in s.instances:
            if g.obj_id != a.obj or g.px_visib < a.min_px or g.mask is None:
                continue
            e = min(by_img[key], key=lambda r, g=g: float(np.linalg.norm(r.t - g.t)))
            p_gt, p_est = P @ g.R.T + g.t, P @ e.R.T + e.t
            add = float(np.linalg.norm(p_gt - p_est, axis=1).mean())
            ang = float(np.degrees(np.arccos(np.clip((np.trace(e.R @ g.R.T) - 1) / 2, -1, 1))))
            uv = p_gt @ s.K.T
            u = np.round(uv[:, 0] / uv[:, 2]).astype(int)
            v = np.round(uv[:, 1] / uv[:, 2]).astype(int)
            h, w = g.mask.shape
            idx = np.where((u >= 0) & (u < w) & (v >= 0) & (v < h))[0]
            vis = np.zeros(len(P), bool)
            vis[idx] = g.mask[v[idx], u[idx]] & (np.abs(s.depth[v[idx], u[idx]] - p_gt[idx, 2]) < a.tol)
            out.append((add < 0.1 * d, ang, (dark & vis).sum() / max(int(vis.sum()), 1)))
    if not out:
        raise SystemExit(f"no GT instance of obj {a.obj} with an estimate")
    arr = np.array(out, dtype=float)
    ok = arr[:, 0] > 0
    print(f"obj {a.obj}: {len(arr)} instances, {int(ok.sum())} correct")
    for name, m in (("missed", ~ok), ("correct", ok)):
        if m.any():
            print(f"{name}: {int(m.sum())}, rotation error median {np.median(arr[m, 1]):.1f} deg, "
                  f"visible dark share median {np.median(arr[m, 2]):.4f}")
            print(f"  rotation errors (deg): {np.sort(arr[m, 1]).round(0).tolist()}")
            print(f"  visible dark shares: {np.sort(arr[m, 2]).round(3).tolist()}")


if __name__ == "__main__":
    main()
