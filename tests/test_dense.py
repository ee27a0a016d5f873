"""Tests of the dense head of the learned stage (sixdpose.pose.dense, PoseNet(head="dense")): the robust
fit, the symmetric targets, training through the engine (resume, predict-pose) and classes without
training instances. Fast: tiny networks on the 160x120 rendered dataset of test_pose."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).parent))
from sixdpose.cli import main  # noqa: E402
from sixdpose.pose import checkpoint as ck  # noqa: E402
from sixdpose.pose.dense import (  # noqa: E402
    Symmetry,
    coordinate_targets,
    dense_loss,
    discover_symmetries,
    ransac_kabsch,
    rotation_about,
    weighted_kabsch,
)
from test_pose import OID, write_pose_dataset  # noqa: E402
from test_reg_helpers import H_SMALL, K_SMALL, W_SMALL, make_shape, render_depth  # noqa: E402

torch.set_num_threads(1)
DENSE = dict(head="dense", epochs=2, repeat=1, batch_size=2, max_images=3)


def _angle_deg(Ra, Rb) -> float:
    return math.degrees(math.acos(np.clip((np.trace(Ra @ Rb.T) - 1) / 2, -1, 1)))


# ---------------------------------------------------------------- robust fit
def test_weighted_kabsch_exact_and_ransac_recovers_pose_with_outliers():
    rng = np.random.default_rng(3)
    R = Rotation.random(random_state=4).as_matrix()
    t = np.array([0.1, -0.05, 0.7])
    src = rng.uniform(-0.06, 0.06, size=(256, 3))
    dst = src @ R.T + t
    R1, t1 = weighted_kabsch(src, dst, rng.uniform(0.1, 1, 256))
    assert np.allclose(R1, R) and np.allclose(t1, t)
    noisy = dst + rng.normal(0, 0.002, size=dst.shape)
    out = rng.random(256) < 0.4  # 40 % gross outliers
    noisy[out] = t + rng.uniform(-0.15, 0.15, size=(out.sum(), 3))
    Rp, tp = weighted_kabsch(src, noisy)  # plain least squares is dragged away by the outliers
    assert _angle_deg(Rp, R) > 2.0 or np.linalg.norm(tp - t) > 0.005
    Rr, tr, inl = ransac_kabsch(src, noisy, threshold=0.008, rng=np.random.default_rng(0))
    assert _angle_deg(Rr, R) < 1.0 and np.linalg.norm(tr - t) < 0.002
    assert inl[~out].mean() > 0.9 and inl[out].mean() < 0.1
    with pytest.raises(ValueError, match=">= 3"):
        ransac_kabsch(src[:2], dst[:2])


def test_ransac_scores_every_hypothesis_as_the_direct_distance_would():
    """ransac_kabsch scores hypotheses with |R s + t - d|^2 expanded into matrix products (speed): the chosen
    hypothesis, its refits and inliers are those of the direct per-point distance, hypotheses drawn alike."""
    from sixdpose.registration.super4pcs import kabsch_batch

    for trial in range(20):
        rng = np.random.default_rng(trial)
        K = int(rng.integers(3, 600))
        src = rng.normal(0, 0.05, size=(K, 3))
        dst = src @ Rotation.random(random_state=trial).as_matrix().T + rng.normal(0, 0.5, 3) + [0, 0, 0.7]
        dst += rng.normal(0, 0.003, size=dst.shape)
        dst[: K // 3] += rng.normal(0, 0.05, size=(K // 3, 3))
        w = rng.uniform(0.1, 1.0, K)
        thr = (0.01, 0.015, 0.06)[trial % 3]
        R, t, inl = ransac_kabsch(src, dst, w, threshold=thr, iterations=64, rng=np.random.default_rng(trial))
        draw = np.random.default_rng(trial).choice(K, size=(64, 3), p=w / w.sum())
        Rs, ts = kabsch_batch(src[draw], dst[draw])
        res = np.linalg.norm(src[None] @ Rs.transpose(0, 2, 1) + ts[:, None] - dst[None], axis=2)  # (M, K)
        best = int(np.argmax(((res < thr) * w).sum(axis=1)))
        Rb, tb, ref = Rs[best], ts[best], res[best] < thr
        for _ in range(2):
            if ref.sum() < 3:
                break
            Rb, tb = weighted_kabsch(src[ref], dst[ref], w[ref])
            ref = np.linalg.norm(src @ Rb.T + tb - dst, axis=1) < thr
        np.testing.assert_array_equal(inl, ref)
        np.testing.assert_allclose(R, Rb, atol=1e-9)
        np.testing.assert_allclose(t, tb, atol=1e-9)


# ---------------------------------------------------------------- symmetric targets
def _instance(rng):
    R = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix()
    t = np.array([0.05, 0.02, 0.6])
    pts_O = rng.uniform(-0.04, 0.04, size=(64, 3))
    return R, t, pts_O @ R.T + t


def _loss_dist(pred, targets):
    coords = torch.from_numpy(pred[None]).float()
    _, d = dense_loss(coords, torch.zeros(1, coords.shape[1]), torch.from_numpy(targets[None]).float())
    return float(d[0])


def test_continuous_and_discrete_symmetric_poses_give_zero_loss():
    rng = np.random.default_rng(0)
    axis, offset = np.array([0.0, 0.0, 1.0]), np.array([0.01, -0.02, 0.03])

    def about_axis(th):  # rotation by th about the axis through offset
        Rc = rotation_about(axis, th)
        return Rc, offset - Rc @ offset

    Rx = rotation_about(np.array([1.0, 0, 0]), math.pi)
    S_flip = (Rx, offset - Rx @ offset)  # a half turn about the x line through offset (maps the axis onto itself)
    cases = {
        "continuous": (Symmetry.build([], axis, offset), about_axis),
        "discrete": (Symmetry.build([S_flip]), lambda th: S_flip),
        "both": (Symmetry.build([S_flip], axis, offset), None),
    }
    for name, (sym, make_S) in cases.items():
        R, t, cloud = _instance(rng)
        pred = coordinate_targets(cloud, R, t, sym)[0]  # a perfect prediction for the pose X
        for th in rng.uniform(0, 2 * math.pi, 4):
            if make_S is None:  # X S_c S_d: a continuous rotation and the flip
                Rc = rotation_about(axis, th)
                Rs, ts = Rc @ S_flip[0], Rc @ S_flip[1] + offset - Rc @ offset
            else:
                Rs, ts = make_S(th)
            R2, t2 = R @ Rs, R @ ts + t  # X S: the same object in the same place
            d = _loss_dist(pred, coordinate_targets(cloud, R2, t2, sym))
            assert d < 1e-5, (name, th, d)
            # without the symmetry the same prediction is wrong for the equivalent pose
            assert _loss_dist(pred, coordinate_targets(cloud, R2, t2, Symmetry.none())) > 1e-3, name
    # the targets fit back to a pose that is symmetric-equivalent to the ground truth
    sym = cases["continuous"][0]
    R, t, cloud = _instance(rng)
    y = coordinate_targets(cloud, R, t, sym)[0]
    Rf, tf = weighted_kabsch(y, cloud)
    model = rng.uniform(-0.04, 0.04, size=(50, 3))
    ring = [about_axis(a) for a in np.linspace(0, 2 * math.pi, 721)]
    err = min(np.abs((model @ (Rf @ Rs).T + Rf @ ts + tf) - (model @ R.T + t)).max() for Rs, ts in ring)
    assert err < 1e-3


def test_discover_symmetries_of_shapes():
    rng = np.random.default_rng(1)
    # a closed cylinder along y (radius 3 cm, height 10 cm): continuous about y, flips about x and z
    n = 4000
    ang, h = rng.uniform(0, 2 * math.pi, n), rng.uniform(-0.05, 0.05, n)
    side = np.stack([0.03 * np.cos(ang), h, 0.03 * np.sin(ang)], 1)
    r = 0.03 * np.sqrt(rng.uniform(0, 1, n // 2))
    a2 = rng.uniform(0, 2 * math.pi, n // 2)
    caps = np.stack([r * np.cos(a2), np.where(rng.random(n // 2) < 0.5, -0.05, 0.05), r * np.sin(a2)], 1)
    cyl = np.concatenate([side, caps]) + [0.01, 0.02, 0.0]
    s = discover_symmetries(cyl, 0.117)
    assert s.axis is not None and abs(abs(s.axis[1]) - 1) < 1e-2
    assert np.allclose(s.offset, [0.01, 0.02, 0.0], atol=2e-3) and len(s.R) >= 2
    # a 10 x 6 x 2 cm box: 180-degree turns about its three axes, no continuous axis
    box = rng.uniform(-1, 1, size=(6000, 3))
    face = rng.integers(0, 3, 6000)
    box[np.arange(6000), face] = np.sign(box[np.arange(6000), face])  # on the surface
    box *= [0.05, 0.03, 0.01]
    s = discover_symmetries(box, 0.12)
    assert s.axis is None and len(s.R) == 4
    # the asymmetric test shape: nothing
    P, _, _, diam = make_shape(0.003, 0)
    assert discover_symmetries(P, diam).trivial


def _cube(rng, n: int = 6000, half: float = 0.03):
    """Points and outward normals on a cube's surface (side 2 * half metres), turned at random and moved off
    the origin, so no principal axis that ``eigh`` returns need be one of its face normals."""
    pts = rng.uniform(-1, 1, size=(n, 3))
    face = rng.integers(0, 3, n)
    sign = np.sign(pts[np.arange(n), face])
    pts[np.arange(n), face] = sign
    normals = np.zeros((n, 3))
    normals[np.arange(n), face] = sign
    R = Rotation.random(random_state=rng).as_matrix()
    return (pts * half) @ R.T + [0.01, -0.02, 0.03], normals @ R.T


def test_discover_symmetries_finds_a_cubes_24_turns_from_its_normals():
    """A cube's principal moments are equal, so its principal axes are arbitrary and the search about them
    finds nothing; its face normals give the axes, and closing the turns found gives all 24. The cube flagged
    asymmetric (texture decides its turn) has 24 shape flips, a closed group; a cap of 4 keeps a subgroup."""
    from sixdpose.datasets.base import ObjectModel
    from sixdpose.pose.dense import _closed, shape_flips

    rng = np.random.default_rng(5)
    P, N = _cube(rng)
    diam = 0.06 * math.sqrt(3)
    assert len(discover_symmetries(P, diam).R) < 24  # the principal axes alone: not the cube's group
    s = discover_symmetries(P, diam, normals=N)
    assert s.axis is None and len(s.R) == 24 and _closed(s.R)
    c = np.array([0.01, -0.02, 0.03])  # the cube's centre
    for R, t in zip(s.R, s.t, strict=True):  # each turn is about the centre (up to the subsample's centroid)
        assert np.allclose(R @ c + t, c, atol=5e-3)
    assert sorted({round(float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))) for R in s.R}) == [
        0, 90, 120, 180]
    cube = ObjectModel("cube", 7, P, N, np.zeros_like(P), diam, False)
    assert len(shape_flips(cube, 24).R) == 24
    f4 = shape_flips(cube, 4)
    assert len(f4.R) == 4 and _closed(f4.R)
    assert len(discover_symmetries(P, diam, normals=N[:10]).R) < 24  # not the points' normals: unknown
    # a thin rod with a loose tolerance: near-turns about its long axis pass the shape test but their products
    # never close into a finite group; the first search's rotations are kept, not MAX_SYMMETRIES of them
    n = 3000
    rod = np.stack([rng.uniform(-0.15, 0.15, n), 0.004 * rng.standard_normal(n), 0.004 * rng.standard_normal(n)], 1)
    rod_n = np.concatenate([np.zeros((n, 1)), rod[:, 1:] / np.linalg.norm(rod[:, 1:], axis=1, keepdims=True)], 1)
    assert len(discover_symmetries(rod, 0.3, normals=rod_n).R) == len(discover_symmetries(rod, 0.3).R)
    # zero normals (unknown) change nothing
    assert len(discover_symmetries(P, diam, normals=np.zeros_like(P)).R) == len(discover_symmetries(P, diam).R)


def test_model_symmetry_reads_bop_annotations():
    from sixdpose.datasets.base import ObjectModel
    from sixdpose.pose.dense import model_symmetry

    P, N, C, diam = make_shape(0.004, 0)
    flip = [1, 0, 0, 20.0, 0, -1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1]  # row-major: half turn about x, 20 mm along x
    ann = {"symmetries_discrete": [flip], "symmetries_continuous": [{"axis": [0, 0, 2], "offset": [5, 0, 0]}]}
    s = model_symmetry(ObjectModel("o", 1, P, N, C, diam, True, symmetries=ann))
    assert np.allclose(s.axis, [0, 0, 1]) and np.allclose(s.offset, [0.005, 0, 0]) and abs(s.ref @ s.axis) < 1e-12
    assert len(s.R) == 2 and np.allclose(s.R[1], np.diag([1, -1, -1])) and np.allclose(s.t[1], [0.02, 0, 0])
    assert model_symmetry(ObjectModel("o", 1, P, N, C, diam, False)).trivial


# ---------------------------------------------------------------- training, resume, inference
def _predict_proper_poses(ds, run, out, n_rows: int, z_range: tuple[float, float], extra: tuple = ()) -> None:
    """``predict-pose`` of ``run`` on ``ds`` (with the arguments ``extra``) writes ``n_rows`` scored rows of proper
    rotations whose translations are finite with a depth inside ``z_range`` (metres: the robust fit puts them on
    the cloud)."""
    from sixdpose.artifacts.poses import read_results

    assert main(["predict-pose", "--data", str(ds), "--pose", str(run), "--out", str(out), "--no-progress",
                 *extra]) == 0
    rows = read_results(out)
    assert len(rows) == n_rows and all(r.score > 0 for r in rows)
    for r in rows:
        assert np.allclose(r.R @ r.R.T, np.eye(3), atol=1e-6) and np.linalg.det(r.R) > 0
        assert np.isfinite(r.t).all() and z_range[0] < r.t[2] < z_range[1]


@pytest.fixture(scope="module")
def pose_ds(tmp_path_factory) -> Path:
    return write_pose_dataset(tmp_path_factory.mktemp("dense") / "ds")


def test_dense_training_resumes_bit_for_bit_and_predict_pose_writes_csv(pose_ds, tmp_path):
    from sixdpose.pose.train import train_pose

    s = train_pose(pose_ds, tmp_path / "a", profile="smoke", progress=False, **DENSE)
    assert s["epochs"] == 2 and np.isfinite(s["last_loss"])
    train_pose(pose_ds, tmp_path / "b", profile="smoke", progress=False, **dict(DENSE, epochs=1))
    s = train_pose(pose_ds, tmp_path / "b", resume=True, progress=False, epochs=2)
    assert s["start_epoch"] == 1 and s["epochs"] == 2
    a, b = ck.load(tmp_path / "a" / ck.LAST), ck.load(tmp_path / "b" / ck.LAST)
    assert a["arch"]["head"] == "dense" and a["global_step"] == b["global_step"]
    assert {k for k in a["model"] if k.startswith("head_")} == {k for k in a["model"] if k.startswith("head_d.")}
    for k in a["model"]:
        assert torch.equal(a["model"][k], b["model"][k]), k
    assert float(a["model"]["seen"][0]) == 2 * 4  # 2 epochs x 3 images, the first with two instances
    _predict_proper_poses(pose_ds, tmp_path / "a", tmp_path / "res.csv", 4, (0.3, 0.9))


def test_dense_head_learns_coordinates(pose_ds, tmp_path):
    """240 smoke steps (about 5 s) on the 3 images: the loss halves and most poses pass ADD at 10 %."""
    from sixdpose.evaluation.evaluate import evaluate
    from sixdpose.pose.infer import predict_dataset
    from sixdpose.pose.train import train_pose

    s = train_pose(pose_ds, tmp_path / "r", profile="smoke", progress=False, head="dense", epochs=60)
    assert s["last_loss"] < 0.6 * s["first_loss"], s
    rows, _ = predict_dataset(pose_ds, tmp_path / "r", device="cpu")
    assert evaluate(pose_ds, rows, min_px=0).accuracy >= 50.0


def test_refiner_refuses_a_dense_run(pose_ds, tmp_path, capsys):
    from sixdpose.pose.train import train_pose

    train_pose(pose_ds, tmp_path / "d", profile="smoke", progress=False, **dict(DENSE, epochs=1))
    assert main(["train-refiner", "--pose", str(tmp_path / "d"), "--data", str(pose_ds), "--out",
                 str(tmp_path / "ref"), "--profile", "smoke"]) == 2
    assert "paper head" in capsys.readouterr().err


def _two_object_dataset(root: Path) -> Path:
    """Object OID in every image; object OID + 1 (another shape) only in the last image."""
    from sixdpose.datasets.layout import write_dataset

    P, N, C, diam = make_shape(0.002, 0)
    Pd, Nd, _, _ = make_shape(0.0012, 0)
    Q, M, D, diam2 = make_shape(0.002, 5)
    Qd, Md, _, _ = make_shape(0.0012, 5)
    rng = np.random.default_rng(0)
    images = []
    for im in range(4):
        objs = [(OID, Pd, Nd, (-0.08, 0.0, 0.6))] + ([(OID + 1, Qd, Md, (0.08, 0.0, 0.6))] if im == 3 else [])
        posed = [(oid, p, n, Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_matrix(), np.asarray(t))
                 for oid, p, n, t in objs]
        depth, label = render_depth([(p, n, R, t) for _, p, n, R, t in posed])
        rgb = np.zeros((H_SMALL, W_SMALL, 3), np.uint8)
        rgb[label >= 0] = (200, 120, 40)
        insts = [{"obj_name": "035_power_drill" if oid == OID else "055_baseball", "obj_id": oid, "inst": 0, "R": R,
                  "t": t, "mask": label == k} for k, (oid, _, _, R, t) in enumerate(posed)]
        images.append({"im_id": im, "scene_id": 0, "K": K_SMALL, "rgb": rgb, "depth": depth, "instances": insts})
    models = {"035_power_drill": {"obj_id": OID, "diameter": diam, "symmetric": False, "points": P, "normals": N,
                                  "colors": C},
              "055_baseball": {"obj_id": OID + 1, "diameter": diam2, "symmetric": False, "points": Q, "normals": M,
                        "colors": D}}
    return write_dataset(root, images, models, {"generator": "tests.test_dense"})


@pytest.mark.parametrize("head", ["dense", "paper"])
def test_class_without_training_instances_is_skipped_with_reason(tmp_path, head):
    from sixdpose.datasets import as_reader
    from sixdpose.pose.infer import predict_dataset
    from sixdpose.pose.train import train_pose

    ds = _two_object_dataset(tmp_path / "ds")
    reader = as_reader(ds)
    assert reader.keys()[-1] == (0, 3)
    s = train_pose(ds, tmp_path / "run", profile="smoke", progress=False, head=head, epochs=1, repeat=1, max_images=3,
                   batch_size=3, val=ds)
    assert s["val_add"] is not None  # validated through the estimator over the networks in memory
    seen = ck.load(tmp_path / "run")["model"]["seen"].tolist()
    assert seen == [3.0, 0.0]  # the last image (the only one with OID + 1) was not trained on
    rows, _ = predict_dataset(ds, tmp_path / "run", device="cpu")
    other = [r for r in rows if r.obj_id == OID + 1]
    assert len(other) == 1 and other[0].score == 0 and "no training instance" in other[0].reason
    assert all(r.score > 0 for r in rows if r.obj_id == OID)


def test_augment_changes_mask_and_depth_within_bounds():
    """Mask jitter stays within its pixel budget, holes and noise only touch the masked depth, and the
    default augmentation is the identity (a run without the fields is unchanged)."""
    from scipy import ndimage

    from sixdpose.pose.data import Augment

    H, W = 60, 80
    mask = np.zeros((H, W), bool)
    mask[20:40, 30:55] = True
    depth = np.full((H, W), 1.0, np.float32)
    rng = np.random.default_rng(0)
    assert np.array_equal(Augment().apply(mask, depth.copy(), rng), mask)
    seen = set()
    for s in range(30):
        d = depth.copy()
        out = Augment(mask_px=3).apply(mask, d, np.random.default_rng(s))
        assert np.array_equal(d, depth)  # depth untouched without depth augmentation
        assert (ndimage.binary_dilation(mask, iterations=3) >= out).all()
        assert (out >= ndimage.binary_erosion(mask, iterations=3)).all()
        seen.add(int(out.sum()) - int(mask.sum()))
    assert any(k > 0 for k in seen) and any(k < 0 for k in seen)
    d = depth.copy()
    out = Augment(holes=0.5, depth_noise=0.01).apply(mask, d, np.random.default_rng(1))
    assert np.array_equal(out, mask)
    assert np.array_equal(d[~mask], depth[~mask])  # nothing outside the mask changes
    assert (d[mask] == 0).any() and (d[mask] >= 0).all()
    assert np.abs(d[mask & (d > 0)] - 1.0).max() < 0.1


def test_occlusion_hides_one_side_of_the_mask_behind_a_straight_edge():
    """``occlusion``: about half the instances lose up to that fraction of their mask, the removed part on one
    side of a straight line (a half-plane), never the whole mask; depth is not touched; 0 is the identity."""
    from sixdpose.pose.data import Augment

    H, W = 60, 80
    mask = np.zeros((H, W), bool)
    mask[10:50, 20:60] = True
    depth = np.full((H, W), 1.0, np.float32)
    cut, fracs = 0, []
    for s in range(60):
        d = depth.copy()
        out = Augment(occlusion=0.5).apply(mask, d, np.random.default_rng(s))
        assert np.array_equal(d, depth) and (out <= mask).all() and out.any()
        lost = mask & ~out
        if not lost.any():
            continue
        cut += 1
        fracs.append(lost.sum() / mask.sum())
        # a half-plane: some line separates the lost pixels from the kept ones (checked over 360 directions)
        v, u = np.nonzero(mask)
        kept = out[v, u]
        ok = False
        for a in np.linspace(0, 2 * np.pi, 360, endpoint=False):
            p = v * np.sin(a) + u * np.cos(a)
            if p[~kept].min() >= p[kept].max() - 1.0:
                ok = True
                break
        assert ok
    assert 15 <= cut <= 45 and max(fracs) <= 0.5 + 0.05 and max(fracs) > 0.3
    assert np.array_equal(Augment(occlusion=0.0).apply(mask, depth.copy(), np.random.default_rng(0)), mask)


def test_crop_window_jitter_moves_and_scales_the_window():
    """Crop jitter moves and scales the window within its bounds; 0 gives the exact box window."""
    from sixdpose.pose.data import crop_window

    mask = np.zeros((100, 100), bool)
    mask[40:60, 30:70] = True
    base = crop_window(mask, 0.1)
    assert crop_window(mask, 0.1, 0.0, np.random.default_rng(0)) == base
    y0, x0, side = crop_window(mask, 0.1, 0.2, np.random.default_rng(0))
    assert (y0, x0, side) != base
    assert base[2] * np.exp(-0.2) - 1e-9 <= side <= base[2] * np.exp(0.2) + 1e-9


def test_the_decoupled_loss_gives_every_point_the_full_coordinate_gradient():
    """``densefusion`` scales a point's coordinate gradient by its confidence; ``decoupled`` does not (the
    confidences still learn from the detached distances); an unknown mode is refused."""
    torch.manual_seed(0)
    target = torch.randn(2, 1, 8, 3)
    logit = torch.linspace(-4, 4, 16).view(2, 8)
    grads = {}
    for mode in ("densefusion", "decoupled"):
        coords = (target[:, 0] + 0.05).clone().requires_grad_(True)
        conf = logit.clone().requires_grad_(True)
        loss, dist = dense_loss(coords, conf, target, mode=mode)
        loss.sum().backward()
        grads[mode] = (coords.grad.norm(dim=2), conf.grad)
        assert torch.allclose(dist, torch.full((2,), 0.05 * math.sqrt(3)), atol=1e-6)
    c = torch.sigmoid(logit)
    assert torch.allclose(grads["densefusion"][0], grads["decoupled"][0] * c, atol=1e-6)  # scaled by c
    assert torch.allclose(grads["decoupled"][0], grads["decoupled"][0][0, 0].expand(2, 8))  # equal for all
    assert torch.allclose(grads["densefusion"][1], grads["decoupled"][1])  # the same confidence gradient
    with pytest.raises(ValueError, match="dense loss mode"):
        dense_loss(target[:, 0], logit, target, mode="l2")


# ---------------------------------------------------------------- shape flips
def _box_model(symmetric: bool = False):
    from sixdpose.datasets.base import ObjectModel

    rng = np.random.default_rng(3)
    box = rng.uniform(-1, 1, size=(6000, 3))
    face = rng.integers(0, 3, 6000)
    box[np.arange(6000), face] = np.sign(box[np.arange(6000), face])
    box = box * [0.05, 0.03, 0.01] + [0.01, 0.0, 0.02]  # off-origin: the turns have translations
    return ObjectModel("box", 2, box, np.zeros_like(box), np.zeros_like(box), 0.12, symmetric)


def _can_model(rng, n: int = 4000):
    """A can (closed cylinder along y, radius 3 cm, height 10 cm) flagged asymmetric: n side points, n / 2 caps."""
    from sixdpose.datasets.base import ObjectModel

    ang, h = rng.uniform(0, 2 * math.pi, n), rng.uniform(-0.05, 0.05, n)
    side = np.stack([0.03 * np.cos(ang), h, 0.03 * np.sin(ang)], 1)
    r, a2 = 0.03 * np.sqrt(rng.uniform(0, 1, n // 2)), rng.uniform(0, 2 * math.pi, n // 2)
    caps = np.stack([r * np.cos(a2), np.where(rng.random(n // 2) < 0.5, -0.05, 0.05), r * np.sin(a2)], 1)
    return ObjectModel("can", 3, np.concatenate([side, caps]), np.zeros((2 * n, 3)), np.zeros((2 * n, 3)), 0.117, False)


def test_shape_flips_canonical_turn_and_unflip_recover_the_pose():
    """A box flagged asymmetric has 4 shape flips; every equivalent pose names the same canonical pose; the
    canonical coordinates fitted back to the cloud and unflipped give the true pose."""
    from sixdpose.pose.dense import canonical_flip, shape_flips, unflip

    model = _box_model()
    fl = shape_flips(model, 8)
    assert len(fl.R) == 4 and np.allclose(fl.R[0], np.eye(3)) and fl.axis is None
    assert len(shape_flips(model, 2).R) == 2 and shape_flips(_box_model(symmetric=True), 8).trivial
    with pytest.raises(ValueError, match="max_flips"):
        shape_flips(model, 0)
    rng = np.random.default_rng(0)
    for _ in range(20):
        R, t = Rotation.random(random_state=rng).as_matrix(), np.array([0.02, -0.01, 0.6])
        d = canonical_flip(R, fl)
        canon, canon_t = R @ fl.R[d], R @ fl.t[d] + t
        for e in range(4):  # the same object seen under an equivalent pose X S_e: the same canonical pose
            Re, te = R @ fl.R[e], R @ fl.t[e] + t
            de = canonical_flip(Re, fl)
            assert np.allclose(Re @ fl.R[de], canon, atol=1e-6) and np.allclose(Re @ fl.t[de] + te, canon_t, atol=1e-6)
        cloud = model.points[:300] @ R.T + t
        y = coordinate_targets(cloud, R, t, fl)[d]
        Rc, tc = weighted_kabsch(y, cloud)  # the fit of the canonical coordinates: X S_d
        assert np.allclose(Rc, canon, atol=1e-6)
        Rb, tb = unflip(Rc, tc, fl.R[d], fl.t[d])
        assert np.allclose(Rb, R, atol=1e-6) and np.allclose(tb, t, atol=1e-6)
    # a can (closed cylinder along y) flagged asymmetric: the identity and one half turn, the axis kept; the
    # canonical turn's axis is the same under every turn about the axis and upside down
    can = _can_model(rng)
    fc = shape_flips(can, 8)
    assert len(fc.R) == 2 and fc.axis is not None and abs(abs(fc.axis[1]) - 1) < 1e-2
    for _ in range(10):
        R = Rotation.random(random_state=rng).as_matrix()
        axis = R @ fc.R[canonical_flip(R, fc)] @ fc.axis
        for phi, e in ((0.7, 0), (2.0, 1), (-1.2, 1)):
            Re = R @ rotation_about(fc.axis, phi) @ fc.R[e]
            assert np.allclose(Re @ fc.R[canonical_flip(Re, fc)] @ fc.axis, axis, atol=1e-6)


def test_view_flip_names_one_canonical_pose_by_where_the_camera_is():
    """flip_canon=view: for a cube (24 turns), a box (4) and a can (a half turn and an axis), every equivalent
    pose X S_e names the same canonical pose; the canonical pose puts the camera on the reference side; a pose
    turned a little (no tie crossed) keeps its turn, so the choice follows what the image shows."""
    from sixdpose.datasets.base import ObjectModel
    from sixdpose.pose.config import PoseConfig
    from sixdpose.pose.dense import _VIEW_REF, flip_centre, shape_flips, view_flip

    rng = np.random.default_rng(11)
    P, N = _cube(rng)
    cube = shape_flips(ObjectModel("cube", 7, P, N, np.zeros_like(P), 0.06 * math.sqrt(3), False), 24)
    assert len(cube.R) == 24
    c = flip_centre(cube)
    assert np.allclose(c, [0.01, -0.02, 0.03], atol=5e-3)  # the cube's centre
    box = shape_flips(_box_model(), 8)
    assert np.allclose(flip_centre(box)[:2], [0.01, 0.0], atol=2e-3)
    for fl in (cube, box):
        cen = flip_centre(fl)
        for _ in range(20):
            R, t = Rotation.random(random_state=rng).as_matrix(), np.array([0.05, -0.03, 0.8])
            d = view_flip(R, t, fl)
            canon, canon_t = R @ fl.R[d], R @ fl.t[d] + t
            cam = (-canon_t) @ canon - cen  # the camera seen from the canonical pose's object frame
            others = [(Rd.T @ ((-canon_t) @ canon - td)) - cen for Rd, td in zip(fl.R, fl.t, strict=True)]
            assert cam @ _VIEW_REF >= max(o @ _VIEW_REF for o in others) - 1e-9
            for e in range(len(fl.R)):
                Re, te = R @ fl.R[e], R @ fl.t[e] + t
                de = view_flip(Re, te, fl)
                assert np.allclose(Re @ fl.R[de], canon, atol=1e-6)
                assert np.allclose(Re @ fl.t[de] + te, canon_t, atol=1e-6)
    # 48 small turns of one pose: the canonical turn stays unless the view crosses a tie (rare)
    R, t = Rotation.random(random_state=rng).as_matrix(), np.array([0.0, 0.0, 0.7])
    d0 = view_flip(R, t, cube)
    same = [view_flip(Rotation.from_rotvec(rng.normal(0, 0.01, 3)).as_matrix() @ R, t, cube) == d0 for _ in range(48)]
    assert sum(same) >= 40
    # a can: the canonical turn has the camera on the + side of its axis, under any turn about it and upside down
    can = _can_model(rng)
    fc = shape_flips(can, 8)
    for _ in range(10):
        R, t = Rotation.random(random_state=rng).as_matrix(), np.array([0.1, 0.0, 0.9])
        d = view_flip(R, t, fc)
        canon, canon_t = R @ fc.R[d], R @ fc.t[d] + t
        assert ((-canon_t) @ canon - flip_centre(fc)) @ fc.axis >= 0
        for e in range(2):
            Re, te = R @ fc.R[e], R @ fc.t[e] + t
            assert np.allclose(Re @ fc.R[view_flip(Re, te, fc)], canon, atol=1e-6)
    with pytest.raises(ValueError, match="flip_canon"):
        PoseConfig(head="dense", flip_canon="camera")


def test_flip_classifier_outputs_and_loss():
    from sixdpose.pose.config import PoseConfig
    from sixdpose.pose.dense import flip_loss
    from sixdpose.pose.model import PoseNet

    net = PoseNet(2, width=1 / 16, head="dense", flips=3)
    with pytest.raises(ValueError, match="room for 1 to 3"):
        net.set_flips({0: (np.eye(3)[None].repeat(4, 0), np.zeros((4, 3)))})
    net.set_flips({1: (np.eye(3)[None].repeat(2, 0), np.zeros((2, 3)))})
    out = net(torch.rand(2, 3, 32, 32), torch.tensor([0, 1]), torch.zeros(2, 16, dtype=torch.long),
              torch.rand(2, 16, 3), torch.tensor([0, 1]))
    lg = out["flip_logit"]
    assert lg.shape == (2, 3) and torch.isinf(lg[0, 1:]).all() and torch.isfinite(lg[1, :2]).all()
    assert torch.isinf(lg[1, 2])
    loss = flip_loss(lg, torch.tensor([0, 1]))
    assert loss[0] == 0 and loss[1] > 0  # a class with one turn has nothing to classify
    assert flip_loss(torch.tensor([[10.0, -10.0]]), torch.tensor([0]))[0] < 1e-6
    assert "flip_logit" not in PoseNet(2, width=1 / 16, head="dense")(
        torch.rand(1, 3, 32, 32), torch.tensor([0]), torch.zeros(1, 16, dtype=torch.long), torch.rand(1, 16, 3),
        torch.tensor([0]))
    with pytest.raises(ValueError, match="flips needs head=dense"):
        PoseConfig(flips=4).validate()
    assert PoseConfig(head="dense", flips=4).arch()["flips"] == 4 and "flips" not in PoseConfig(head="dense").arch()


def _quadrant_colours(P: np.ndarray) -> np.ndarray:
    """Colours of a box's points by the signs of their x and y (red, green, blue, yellow): each of the box's
    four turns shows another pattern."""
    pal = np.array([[0.9, 0.1, 0.1], [0.1, 0.8, 0.1], [0.1, 0.2, 0.9], [0.9, 0.8, 0.1]])
    return pal[(P[:, 0] < 0).astype(int) + 2 * (P[:, 1] < 0).astype(int)]


def _box_dataset(root: Path, colours: bool = False) -> tuple[Path, np.ndarray]:
    """Two rendered frames of a 10 x 6 x 3 cm box flagged asymmetric (obj 2), on the test_reg_helpers camera;
    the model's colours uniform grey or, with ``colours``, by quadrant. Returns ``(dataset, model points)``."""
    from scipy.spatial.transform import Rotation as Rot

    from sixdpose.datasets.layout import write_dataset
    from test_reg_helpers import _box_surface

    rng = np.random.default_rng(0)
    P, N = _box_surface((-0.05, -0.03, -0.015), (0.05, 0.03, 0.015), 0.002, rng)
    images = []
    for im in range(2):
        R, t = Rot.from_rotvec(rng.normal(size=3) * 0.4).as_matrix(), np.array([0.0, 0.0, 0.55])
        depth, label = render_depth([(P, N, R, t)])
        rgb = np.zeros((H_SMALL, W_SMALL, 3), np.uint8)
        rgb[label >= 0] = (200, 120, 40)
        images.append({"im_id": im, "scene_id": 0, "K": K_SMALL, "rgb": rgb, "depth": depth,
                       "instances": [{"obj_name": "035_power_drill", "obj_id": 2, "inst": 0, "R": R, "t": t,
                                      "mask": label == 0}]})
    models = {"035_power_drill": {"obj_id": 2, "diameter": 0.12, "symmetric": False, "points": P, "normals": N,
                                  "colors": _quadrant_colours(P) if colours else np.full_like(P, 0.5)}}
    return write_dataset(root, images, models, {"generator": "tests.test_dense"}), P


def test_training_with_flips_stores_them_and_predict_pose_applies_them(tmp_path):
    """A box flagged asymmetric: a run with flips=4 keeps the box's 4 turns in its weights and predict-pose
    writes proper poses on the cloud."""
    from sixdpose.pose.train import train_pose

    ds, _ = _box_dataset(tmp_path / "box")
    train_pose(ds, tmp_path / "r", profile="smoke", progress=False, **dict(DENSE, flips=4))
    ckpt = ck.load(tmp_path / "r" / ck.LAST)
    assert ckpt["arch"]["flips"] == 4 and int(ckpt["model"]["flip_n"][0]) == 4
    assert np.allclose(ckpt["model"]["flip_R"][0, 0].numpy(), np.eye(3))
    _predict_proper_poses(ds, tmp_path / "r", tmp_path / "res.csv", 2, (0.4, 0.7))


# ---------------------------------------------------------------- geometry alone, flips named by colour
def test_colour_scores_rank_the_true_turn_of_a_coloured_box_first():
    """Each of a quadrant-coloured box's four turns, seen from above, scores below the true pose."""
    from sixdpose.geometry import X_from
    from sixdpose.pose.dense import shape_flips, unflip
    from sixdpose.registration.verify import build_grid, colour_scores

    model = _box_model()
    colors = _quadrant_colours(model.points - model.points.mean(axis=0))
    grid = build_grid(model.points, colors, model.diameter)
    fl = shape_flips(model, 4)
    rng = np.random.default_rng(1)
    for _ in range(5):
        R, t = Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_matrix(), np.array([0.01, 0.02, 0.6])
        p_C = model.points @ R.T + t
        seen = p_C[p_C[:, 2] < np.percentile(p_C[:, 2], 40)]  # the near side
        cols = colors[p_C[:, 2] < np.percentile(p_C[:, 2], 40)]
        order = rng.permutation(4)  # the true pose (turn 0) at a random place among the candidates
        cands = np.stack([X_from(*unflip(R, t, fl.R[d], fl.t[d])) for d in order])
        sc = colour_scores(cands, seen, cols, grid, model.diameter)
        assert order[int(np.argmax(sc))] == 0 and np.isfinite(sc).all()
        # points nowhere near the model: no score
        assert np.isneginf(colour_scores(cands, seen + 5.0, cols, grid, model.diameter)).all()


def test_colour_scores_of_every_candidate_in_one_pass_equal_the_kernel_per_candidate():
    """colour_scores' one compiled pass over the candidates (_poses_kernel) gives, for each candidate, what the
    search's kernel (_score_kernel) gives on that candidate's points within the grid's radius, combined as
    col + cv_geo_weight * geo * (share of the points kept); -inf where fewer than 4 are kept."""
    from sixdpose.geometry import X_from
    from sixdpose.registration.presets import PRESETS
    from sixdpose.registration.verify import SMOOTH_K, _score_kernel, build_grid, chroma, colour_scores

    cfg = PRESETS["default"]
    model = _box_model()
    colors = _quadrant_colours(model.points - model.points.mean(axis=0))
    grid = build_grid(model.points, colors, model.diameter)
    rng = np.random.default_rng(3)
    R, t = Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_matrix(), np.array([0.01, 0.02, 0.6])
    near = (model.points @ R.T + t)[:, 2] < np.percentile((model.points @ R.T + t)[:, 2], 40)
    seen, cols = (model.points @ R.T + t)[near], colors[near] * rng.uniform(0.8, 1.0, (near.sum(), 1))
    cands = np.stack([X_from(Rotation.from_rotvec(rng.normal(size=3) * a).as_matrix() @ R,
                             t + rng.normal(size=3) * s) for a, s in [(0, 0), (0.3, 0.005), (2.0, 0.02), (0, 5.0)]])
    cands = np.concatenate([cands[:3], [X_from(R, t + [0.9 * grid.radius, 0, 0])], cands[3:]])  # part outside
    got = colour_scores(cands, seen, cols, grid, model.diameter, cfg)
    # the reference: the same pooled points and smoothed colours, then the kernel candidate by candidate
    P = np.asarray(seen, float)
    pool = np.random.default_rng(cfg.seed).choice(len(P), size=min(len(P), 2000), replace=False)
    sel = pool[: min(len(pool), cfg.cv_points)]
    k = min(SMOOTH_K, len(pool))
    from scipy.spatial import cKDTree

    dist, nb = cKDTree(P[pool]).query(P[sel], k=k, distance_upper_bound=cfg.cv_smooth_rel * model.diameter)
    ok = np.isfinite(dist)
    ch = chroma(cols[pool])
    fs = (ch[np.where(ok, nb, 0)] * ok[..., None]).sum(axis=1) / ok.sum(axis=1, keepdims=True)
    fs -= fs.mean(axis=0)
    geo, col = np.empty(1), np.empty(1)
    kept = []
    for X, g in zip(cands, got, strict=True):
        v = (P[sel] - X[:3, 3]) @ X[:3, :3] - grid.centroid
        inside = np.linalg.norm(v, axis=1) < grid.radius
        kept.append(inside.mean())
        if inside.sum() < 4:
            assert np.isneginf(g)
            continue
        _score_kernel(v[inside].astype(np.float32), np.eye(3, dtype=np.float32)[None],
                      grid.centroid.astype(np.float32), grid.origin.astype(np.float32), np.float32(1.0 / grid.cell),
                      int(grid.shape[1]), int(grid.shape[2]), grid.weights(cfg.cv_coarse_sigma_rel * model.diameter),
                      grid.smooth, fs[inside].astype(np.float32), geo, col)
        assert abs(g - (col[0] + cfg.cv_geo_weight * geo[0] * inside.mean())) < 1e-4
    assert np.isfinite(got[:4]).all() and np.isneginf(got[4]) and got[0] > got[2] and 0.1 < kept[3] < 0.9


def test_geometry_only_network_has_no_cnn_and_config_checks():
    from sixdpose.errors import ConfigError
    from sixdpose.pose.config import PoseConfig
    from sixdpose.pose.infer import check_inference_overrides
    from sixdpose.pose.model import PoseNet

    net = PoseNet(2, width=1 / 16, head="dense", flips=2, appearance="none")
    assert net.cnn is None and not any(k.startswith("cnn.") for k in net.state_dict())
    out = net(torch.rand(2, 3, 32, 32), torch.tensor([0, 1]), torch.zeros(2, 16, dtype=torch.long),
              torch.rand(2, 16, 3), torch.tensor([0, 1]))
    assert out["coords"].shape == (2, 16, 3) and not out["emb"].any()
    # appearance=local: no CNN either; the embedding is the local shape, the same for each point wherever it
    # comes in the cloud (permutation-equivariant) and nonzero
    loc = PoseNet(2, width=1 / 16, head="dense", appearance="local").eval()
    assert loc.cnn is None and loc.local is not None
    cloud = torch.rand(1, 40, 3) * 0.1
    perm = torch.randperm(40)
    e1 = loc(None, None, torch.zeros(1, 40, dtype=torch.long), cloud, torch.tensor([0]))["emb"]
    e2 = loc(None, None, torch.zeros(1, 40, dtype=torch.long), cloud[:, perm], torch.tensor([0]))["emb"]
    assert e1.shape == (1, loc.emb_dim, 40) and e1.abs().sum() > 0
    assert torch.allclose(e1[..., perm], e2, atol=1e-5)
    # appearance=local_rgb: the points' pixel colours join the local shape; a uniform exposure change of the
    # image does not change the embedding (colours standardised per instance), a different pattern does
    rgb = PoseNet(2, width=1 / 16, head="dense", appearance="local_rgb").eval()
    assert rgb.cnn is None and rgb.local is not None and rgb.local.colour
    img = torch.rand(1, 3, 8, 8)
    choose = torch.randint(0, 64, (1, 40))
    run = lambda im: rgb(im, torch.tensor([0]), choose, cloud, torch.tensor([0]))["emb"]  # noqa: E731
    assert torch.allclose(run(img), run(1.7 * img - 0.2), atol=3e-3)
    assert not torch.allclose(run(img), run(img.flip(1)), atol=3e-2)
    with pytest.raises(ValueError, match="needs head=dense"):
        PoseConfig(appearance="none").validate()
    with pytest.raises(ValueError, match="appearance must be one of"):
        PoseConfig(head="dense", appearance="depth").validate()
    with pytest.raises(ValueError, match="flip_choice must be one of"):
        PoseConfig(head="dense", flip_choice="texture").validate()
    assert PoseConfig(head="dense", appearance="none").arch()["appearance"] == "none"
    assert "appearance" not in PoseConfig(head="dense").arch()  # checkpoints with a CNN keep their arch
    assert check_inference_overrides({"flip_choice": "colour"}) == {"flip_choice": "colour"}
    with pytest.raises(ConfigError, match="flip_choice"):
        check_inference_overrides({"flip_choice": "coin"})


def test_geometry_only_run_names_the_turn_by_the_model_colours(tmp_path):
    """A geometry-only run (appearance=local) with flips on a quadrant-coloured box: inference names the turn
    by colour (flip_choice auto), the canonical pose of the true pose is turned back to the true pose, and a
    grey model (no colour to tell the turns apart) or flip_choice=classifier leaves it to the classifier."""
    from types import SimpleNamespace

    from sixdpose.datasets.readers import open_dataset
    from sixdpose.pose.dense import canonical_flip, shape_flips, unflip
    from sixdpose.pose.infer import Estimator
    from sixdpose.pose.train import train_pose

    ds, P = _box_dataset(tmp_path / "box", colours=True)
    train_pose(ds, tmp_path / "r", profile="smoke", progress=False, **dict(DENSE, flips=4, appearance="local"))
    ckpt = ck.load(tmp_path / "r" / ck.LAST)
    assert ckpt["arch"]["appearance"] == "local" and not any(k.startswith("cnn.") for k in ckpt["model"])
    reader = open_dataset(ds)
    est = Estimator(tmp_path / "r", reader=reader, device="cpu")
    assert est.colour_flips and est.settings()["colour_flips"]
    fl = shape_flips(reader.model(2), 4)
    rng = np.random.default_rng(2)
    cols = _quadrant_colours(P)
    named = set()
    for e in range(4):  # poses in each of the box's turns: the canonical turn differs between them
        R, t = Rotation.from_rotvec(rng.normal(size=3) * 0.4).as_matrix() @ fl.R[e], np.array([0.0, 0.01, 0.55])
        p_C = P @ R.T + t
        near = p_C[:, 2] < np.percentile(p_C[:, 2], 40)
        inst = SimpleNamespace(obj_id=2, points=p_C[near], colors=cols[near], score=1.0)
        d = canonical_flip(R, fl)
        Rc, tc = R @ fl.R[d], R @ fl.t[d] + t  # what the fit of canonical coordinates gives
        assert est._colour_flip(inst, Rc, tc, 0) == (d, -1)
        named.add(d)
        Rb, tb = unflip(Rc, tc, fl.R[d], fl.t[d])
        assert np.allclose(Rb, R, atol=1e-6) and np.allclose(tb, t, atol=1e-6)
    assert len(named) > 1
    by_classifier = Estimator(tmp_path / "r", reader=reader, device="cpu", overrides={"flip_choice": "classifier"})
    assert not by_classifier.colour_flips
    assert not Estimator(tmp_path / "r", device="cpu").colour_flips  # no reader: no model colours (a warning)
    _predict_proper_poses(ds, tmp_path / "r", tmp_path / "res.csv", 2, (0.4, 0.7))


def test_colour_slides_name_where_along_its_long_axis_a_partly_seen_box_is(tmp_path):
    """``colour_slides``: with the turns named by colour, each turn is also scored slid along an elongated model's
    longest axis (the verification's slides). A 10 cm box seen only from x > -2 cm and fitted 2 cm along its
    length from the truth: the slide back is named, with the turn; the fitted pose itself is kept when it is
    right; ``colour_slides=0`` and a model not elongated enough score no slides."""
    from types import SimpleNamespace

    from sixdpose.datasets.readers import open_dataset
    from sixdpose.geometry import X_from
    from sixdpose.pose.dense import canonical_flip, shape_flips
    from sixdpose.pose.infer import Estimator
    from sixdpose.pose.train import train_pose

    ds, P = _box_dataset(tmp_path / "box", colours=True)
    train_pose(ds, tmp_path / "r", profile="smoke", progress=False, **dict(DENSE, flips=4, appearance="local"))
    reader = open_dataset(ds)
    est = Estimator(tmp_path / "r", reader=reader, device="cpu")  # colour_slides=3, the default
    S = est._slides(2)
    assert S.shape == (6, 4, 4) and np.allclose(S[:, :3, :3], np.eye(3))
    assert np.allclose(np.abs(S[:, :3, 3]).max(axis=1), [0.01, 0.01, 0.02, 0.02, 0.03, 0.03], atol=1e-3)
    assert len(Estimator(tmp_path / "r", reader=reader, device="cpu", overrides={"colour_slides": 0})._slides(2)) == 0
    narrow = Estimator(tmp_path / "r", reader=reader, device="cpu",
                       overrides={"colour_slides": 3, "verify_slide_min_elong": 2.0})
    assert len(narrow._slides(2)) == 0  # 10 x 6 cm: not twice as long as wide
    fl = shape_flips(reader.model(2), 4)
    cols = _quadrant_colours(P)
    R, t = Rotation.from_rotvec([0.3, -0.25, 0.2]).as_matrix() @ fl.R[1], np.array([0.0, 0.01, 0.55])
    seen = P[:, 0] > -0.02  # one end hidden (the model's x is its long axis)
    p_C = P[seen] @ R.T + t
    front = p_C[:, 2] < np.percentile(p_C[:, 2], 50)
    inst = SimpleNamespace(obj_id=2, points=p_C[front], colors=cols[seen][front], score=1.0)
    d = canonical_flip(R, fl)
    Rc, tc = R @ fl.R[d], R @ fl.t[d] + t  # the canonical fit of the true pose
    assert est._colour_flip(inst, Rc, tc, 0, S) == (d, -1)
    off = tc + R @ np.array([0.02, 0.0, 0.0])  # the canonical fit 2 cm along the box's length
    dn, s = est._colour_flip(inst, Rc, off, 0, S)
    assert dn == d and s >= 0
    back = X_from(*est._turned(Rc, off, 0, dn)) @ S[s]  # as _dense_poses: the named turn, then the slide
    assert np.allclose(back[:3, :3], R, atol=1e-6) and np.linalg.norm(back[:3, 3] - t) < 1e-3  # the samples' axis
    assert est._colour_flip(inst, Rc, off, 0)[1] == -1  # no slides given: none named
    for extra in ((), ("--icp",), ("--set", "colour_slides=0")):
        _predict_proper_poses(ds, tmp_path / "r", tmp_path / "res.csv", 2, (0.4, 0.7), extra)


def test_pca_input_frame_makes_the_dense_head_blind_to_turns_of_the_view(tmp_path):
    """input_frame=pca: the network sees the centred cloud in its own principal axes, so turning the cloud about
    the camera centre (the object turned in front of the camera) leaves the predicted object coordinates as they
    were (they live in the object frame); in the camera frame they change. The frame is a proper rotation whose
    least-spread axis faces the camera, the canonical flip is chosen in it, and a run trains and predicts."""
    from sixdpose.pose.config import PoseConfig
    from sixdpose.pose.dense import Symmetry, canonical_flip
    from sixdpose.pose.model import PoseNet, pca_frame
    from sixdpose.pose.train import train_pose

    rng = np.random.default_rng(0)
    p = rng.normal(size=(1, 200, 3)) * np.array([0.06, 0.03, 0.01])
    p[..., 0] += rng.exponential(0.01, size=(1, 200))  # a third moment along the long axis: its sign is fixed
    p += np.array([0.05, -0.02, 0.8])
    Q = Rotation.from_rotvec([0.3, -0.2, 0.25]).as_matrix()
    clouds = [torch.tensor(p, dtype=torch.float32), torch.tensor(p @ Q.T, dtype=torch.float32)]
    cen = clouds[0].mean(dim=1)
    V = pca_frame(clouds[0] - cen[:, None], cen)[0].double().numpy()
    assert np.allclose(V.T @ V, np.eye(3), atol=1e-5) and np.linalg.det(V) > 0.999
    assert V[:, 2] @ -cen[0].double().numpy() > 0 and abs(V[:, 0] @ [1.0, 0, 0]) > 0.95
    coords = {}
    for frame in ("camera", "pca"):
        torch.manual_seed(0)
        net = PoseNet(2, width=1 / 8, emb_dim=8, norm="group", head="dense", flips=2, appearance="local",
                      input_frame=frame).eval()
        with torch.no_grad():
            outs = [net(None, None, torch.zeros(1, 200, dtype=torch.long), c, torch.tensor([0])) for c in clouds]
        coords[frame] = (outs[1]["coords"] - outs[0]["coords"]).abs().max().item()
        assert ("frame" in outs[0]) == (frame == "pca")
    assert coords["pca"] < 1e-4 < 1e-3 < coords["camera"]
    # the canonical turn is chosen in the frame the network sees: turning camera and frame together keeps it
    half = Rotation.from_rotvec([0, 0, math.pi]).as_matrix()
    flips = Symmetry.build([(np.eye(3), np.zeros(3)), (half, np.zeros(3))])
    for R in Rotation.random(20, random_state=1).as_matrix():
        assert canonical_flip(R, flips, V) == canonical_flip(Q @ R, flips, Q @ V)
    assert canonical_flip(R, flips, np.eye(3)) == canonical_flip(R, flips)
    with pytest.raises(ValueError, match="input_frame=.pca. needs head=dense"):
        PoseConfig(input_frame="pca").validate()
    with pytest.raises(ValueError, match="input_frame must be one of"):
        PoseConfig(head="dense", input_frame="world").validate()
    assert "input_frame" not in PoseConfig(head="dense").arch()  # earlier runs keep their arch
    ds, _ = _box_dataset(tmp_path / "box", colours=True)
    train_pose(ds, tmp_path / "r", profile="smoke", progress=False,
               **dict(DENSE, flips=4, appearance="local", input_frame="pca"))
    assert ck.load(tmp_path / "r" / ck.LAST)["arch"]["input_frame"] == "pca"
    _predict_proper_poses(ds, tmp_path / "r", tmp_path / "res.csv", 2, (0.4, 0.7))


def test_with_icp_the_colours_name_the_turn_after_icp(tmp_path, monkeypatch):
    """With ``--icp`` a run whose flips are named by the model's colours names the turn after ICP of the fitted
    canonical pose: a fit a few centimetres off across the box makes the quadrant colours name another turn, ICP
    brings the pose onto the cloud (the turns are symmetries of the shape, so one ICP serves them all) and the
    colours then name the true one; ``predict`` runs that ICP once for each instance of a class with flips."""
    from types import SimpleNamespace

    from sixdpose.datasets.readers import open_dataset
    from sixdpose.pose.dense import canonical_flip, shape_flips
    from sixdpose.pose.infer import Estimator
    from sixdpose.pose.train import train_pose

    ds, P = _box_dataset(tmp_path / "box", colours=True)
    train_pose(ds, tmp_path / "r", profile="smoke", progress=False, **dict(DENSE, flips=4, appearance="local"))
    reader = open_dataset(ds)
    est = Estimator(tmp_path / "r", reader=reader, device="cpu", icp=True)
    fl = shape_flips(reader.model(2), 4)
    cols = _quadrant_colours(P)
    R, t = Rotation.from_rotvec([0.35, -0.3, 0.2]).as_matrix() @ fl.R[1], np.array([0.0, 0.01, 0.55])
    p_C = P @ R.T + t
    near = p_C[:, 2] < np.percentile(p_C[:, 2], 40)
    inst = SimpleNamespace(obj_id=2, points=p_C[near], colors=cols[near], score=1.0)
    d = canonical_flip(R, fl)
    Rc, tc = R @ fl.R[d], R @ fl.t[d] + t
    off = tc + Rc @ np.array([0.0, -0.03, 0.0])  # 3 cm across the box, half its width
    assert est._colour_flip(inst, Rc, off, 0)[0] != d
    Ri, ti = est._icp(inst, Rc, off)
    assert np.linalg.norm(ti - tc) < 0.005 and est._colour_flip(inst, Ri, ti, 0) == (d, -1)
    calls = []
    icp = est._icp
    est._icp = lambda *a: calls.append(1) or icp(*a)
    # _post does not run that ICP again where the canonical turn was kept (icp_done), and does where a turn was
    # named (a near-symmetry only): every refine_pose is the naming ICP's or a _post of a turned pose
    import sixdpose.registration as registration

    refines, done = [], []
    refine = registration.refine_pose
    monkeypatch.setattr(registration, "refine_pose", lambda *a, **k: refines.append(1) or refine(*a, **k))
    post = est._post
    est._post = lambda *a, icp_done=False: done.append(icp_done) or post(*a, icp_done=icp_done)
    s = reader.load(reader.keys()[0])
    rows = est.predict(s)
    assert len(calls) == len(rows) == len(done) == 1
    assert len(refines) == len(calls) + sum(not d for d in done)
    n = len(refines)
    kept = est._post(inst, Ri, ti, icp_done=True)
    assert kept[0] is Ri and kept[1] is ti and len(refines) == n
    R2, t2, _ = est._post(inst, Rc, off, icp_done=False)
    assert len(refines) == n + 1 and np.linalg.norm(t2 - off) > 0.005
