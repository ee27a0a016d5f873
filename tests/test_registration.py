"""Geometry, the three methods (+ ICP), the register runner / CLI and the evaluate CLI."""

import csv
import dataclasses

import numpy as np
import pytest

from sixdpose.artifacts.poses import PoseEstimate as Estimate
from sixdpose.artifacts.poses import read_results
from sixdpose.artifacts.predictions import PredictionError, read_predictions
from sixdpose.cli import main
from sixdpose.datasets import open_dataset
from sixdpose.evaluation.evaluate import EvaluationError, evaluate
from sixdpose.registration import geometry
from sixdpose.registration.geometry import ReferenceCache, backproject
from sixdpose.registration.methods import estimate_pose
from sixdpose.registration.presets import PRESETS, get_preset
from sixdpose.registration.runner import run_registration
from test_reg_helpers import YCBV, results_without_time, write_synthetic_dataset

needs_ycbv = pytest.mark.skipif(not YCBV.is_dir(), reason="shared/data/ycbv_sample not available")


@pytest.fixture(scope="module")
def syn(tmp_path_factory):
    return write_synthetic_dataset(tmp_path_factory.mktemp("syn") / "d", n_images=3)


def _register(data, method: str, *args: str) -> int:
    """Exit status of ``sixdpose register --data DATA --method METHOD ARGS...``."""
    return main(["register", "--data", str(data), "--method", method, *args])


def test_backproject_matches_pinhole_loop():
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.4, 1.0, (6, 8)).astype(np.float32)
    depth[0, 0] = 0.0
    depth[1, 1] = np.nan
    mask = np.ones_like(depth, bool)
    mask[2, 3] = False
    rgb = rng.integers(0, 255, (6, 8, 3), dtype=np.uint8)
    K = np.array([[100.0, 0, 3.5], [0, 110.0, 2.5], [0, 0, 1]])
    pts, col, pix = backproject(depth, K, mask, rgb)
    ref = []
    for v in range(6):
        for u in range(8):
            z = depth[v, u]
            if mask[v, u] and np.isfinite(z) and z > 0:
                ref.append([(u - 3.5) * z / 100.0, (v - 2.5) * z / 110.0, z])
    np.testing.assert_allclose(pts, np.array(ref), rtol=1e-6)
    assert len(pts) == 6 * 8 - 3
    np.testing.assert_allclose(col * 255, rgb[pix[:, 0], pix[:, 1]])
    # reprojection gives back the pixel
    uv = (K @ (pts / pts[:, 2:]).T).T
    np.testing.assert_allclose(uv[:, :2], pix[:, ::-1], atol=1e-6)
    with pytest.raises(ValueError, match="mask shape"):
        backproject(depth, K, np.ones((2, 2), bool))


def test_backproject_inside_the_mask_box_is_the_full_image_answer():
    """backproject works inside the mask's bounding box only (speed): the same points, colours and pixels, in
    the same order, as the whole-image computation; an empty mask gives no point; mask_box bounds the mask."""
    from sixdpose.datasets.geometry import mask_box

    rng = np.random.default_rng(1)
    depth = rng.uniform(0.4, 1.0, (48, 64)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.1] = 0.0
    rgb = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)
    K = np.array([[100.0, 0, 31.5], [0, 100.0, 23.5], [0, 0, 1]])
    mask = np.zeros(depth.shape, bool)
    mask[7:20, 30:61] = rng.random((13, 31)) < 0.7
    assert mask_box(mask) == (int(np.nonzero(mask)[0].min()), int(np.nonzero(mask)[0].max()) + 1,
                              int(np.nonzero(mask)[1].min()), int(np.nonzero(mask)[1].max()) + 1)
    pts, col, pix = backproject(depth, K, mask, rgb)
    v, u = np.nonzero(mask & (depth > 0))
    np.testing.assert_array_equal(pix, np.stack([v, u], axis=1))
    np.testing.assert_allclose(pts[:, 2], depth[v, u])
    np.testing.assert_allclose(pts[:, 0], (u - 31.5) * depth[v, u] / 100.0, rtol=1e-6)
    np.testing.assert_allclose(col * 255, rgb[v, u])
    assert mask_box(np.zeros_like(mask)) is None
    pts, col, pix = backproject(depth, K, np.zeros_like(mask), rgb)
    assert pts.shape == (0, 3) and col.shape == (0, 3) and pix.shape == (0, 2)


def test_normals_face_the_camera():
    # a tilted plane in front of the camera
    x, y = np.meshgrid(np.linspace(-0.1, 0.1, 30), np.linspace(-0.1, 0.1, 30))
    pts = np.c_[x.ravel(), y.ravel(), 0.8 + 0.3 * x.ravel()]
    pcd = geometry.estimate_normals(geometry.to_o3d(pts), knn=10)
    n = np.asarray(pcd.normals)
    assert (n[:, 2] < 0).all()
    true = np.array([0.3, 0.0, -1.0]) / np.linalg.norm([0.3, 0, -1])
    assert np.degrees(np.arccos(np.clip(n @ true, -1, 1))).max() < 2.0


def test_reference_cache_reuses_and_downsamples(syn):
    ds = open_dataset(syn)
    cache = ReferenceCache(ds)
    r1, t1 = cache.get(15, 0.005, 0.025)
    r2, t2 = cache.get(15, 0.005, 0.025)
    assert r1 is r2 and t1 > 0 and t2 == 0.0
    assert len(r1.points) < len(ds.model(15).points) and r1.fpfh.data.shape == (33, len(r1.points))
    np.testing.assert_allclose(np.linalg.norm(r1.normals, axis=1), 1.0, atol=1e-6)


@pytest.fixture(scope="module")
def views(syn):
    """Three full-resolution (640x480) renders of the test object at known poses."""
    from test_reg_helpers import look_pose, make_shape, render_depth

    P, N, _, _ = make_shape(0.0006, 1)
    K = np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]])
    out = []
    for k in (0, 2, 3):
        R, t = look_pose(k, (0.0, 0.0, 0.6))
        depth, label = render_depth([(P, N, R, t)], K, 480, 640)
        out.append((backproject(depth, K, label == 0)[0], R, t))
    return out


@pytest.mark.parametrize(
    "method,icp,tol",
    [
        ("super4pcs", False, 0.1),
        ("super4pcs", True, 0.02),
        ("ransac", True, 0.02),
        pytest.param(
            "fgr",
            True,
            0.02,
            marks=pytest.mark.xfail(
                reason="FGR on FPFH fails on most partial views of this shape (known, see report)", strict=True
            ),
        ),
    ],
)
def test_methods_on_rendered_views(syn, views, method, icp, tol):
    """Each method recovers at least 2 of 3 rendered views within tol x diameter (ADD)."""
    from sixdpose.evaluation.metrics import add

    ds = open_dataset(syn)
    m = ds.model(15)
    cfg = get_preset("default", scene_voxel_rel=0.025, model_voxel_rel=0.025)
    cache = ReferenceCache(ds)
    errs = []
    for pts, R, t in views:
        est = estimate_pose(pts, 15, method, cache, cfg, icp=icp)
        assert est.X_CO.shape == (4, 4) and est.time > 0 and 0 <= est.score <= 1
        np.testing.assert_allclose(est.X_CO[:3, :3] @ est.X_CO[:3, :3].T, np.eye(3), atol=1e-6)
        assert np.linalg.det(est.X_CO[:3, :3]) == pytest.approx(1.0)
        errs.append(add(est.X_CO[:3, :3], est.X_CO[:3, 3], R, t, m.points))
    assert sum(e < tol * m.diameter for e in errs) >= 2, errs


def test_presets_behaviour(syn):
    """Presets are validated configs; the paper preset keeps the full masked cloud (section IV-B)
    while the default one downsamples it; an override changes exactly that field."""
    from sixdpose.errors import ConfigError
    from sixdpose.registration.geometry import backproject
    from sixdpose.registration.methods import prepare_scene

    with pytest.raises(ConfigError, match="bogus"):
        get_preset("default", bogus=1)
    fast, default = get_preset("fast"), get_preset("default")
    assert {f.name for f in dataclasses.fields(fast) if getattr(fast, f.name) != getattr(default, f.name)} == {
        "ransac_max_iteration"}
    with pytest.raises(ConfigError, match="unknown profile"):
        get_preset("nope")
    with pytest.raises(ConfigError, match="icp_kind"):
        get_preset("default", icp_kind="sideways")
    assert get_preset("default", cv_rotations=512).cv_rotations == 512
    s = open_dataset(syn)[1]
    pts = backproject(s.depth, s.K, s.instances[0].mask)[0]
    d = open_dataset(syn).model(15).diameter
    full = prepare_scene(pts, d, PRESETS["paper"], features=False)
    down = prepare_scene(pts, d, PRESETS["default"], features=False)
    assert len(full.points) == len(pts) > len(down.points)


def test_runner_writes_bop_rows_and_evaluates(syn, tmp_path):
    out = tmp_path / "r.csv"
    assert _register(syn, "super4pcs", "--icp", "--out", str(out), "--workers", "1", "--no-progress") == 0
    with open(out) as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["scene_id", "im_id", "obj_id", "score", "R", "t", "time"]
    assert len(rows) == 4  # image 0 has two instances of the same object: both registered
    assert [(r["scene_id"], r["im_id"]) for r in rows] == [("0", "0"), ("0", "0"), ("1", "1"), ("0", "2")]
    assert len(rows[0]["R"].split()) == 9 and len(rows[0]["t"].split()) == 3
    assert 400 < float(rows[2]["t"].split()[2]) < 700  # millimetres
    assert rows[0]["time"] == rows[1]["time"]  # BOP: time of the whole image on each of its rows
    ests = read_results(out)
    res = evaluate(open_dataset(syn), ests, min_px=50)
    assert res.n_gt == 4 and res.accuracy == 100.0
    assert res.fps > 0 and res.instances_per_s == pytest.approx(4 * res.fps / 3)
    ev = tmp_path / "ev"
    assert main(["evaluate", "--data", str(syn), "--results", str(out), "--out", str(ev), "--min-px", "50"]) == 0
    with open(ev / "add_s_per_object.csv") as fh:
        table = list(csv.DictReader(fh))
    assert table[0]["obj_id"] == "15" and float(table[-2]["add_s_accuracy"]) == 100.0
    assert "tabular" in (ev / "add_s.tex").read_text()
    assert (ev / "timing.csv").is_file()


def test_evaluate_matching_and_min_px(syn):
    ds = open_dataset(syn)
    s0 = ds[0]
    g0, g1 = s0.instances
    good = [Estimate(0, 0, 15, 0.9, g1.R, g1.t, 0.1), Estimate(0, 0, 15, 0.8, g0.R, g0.t, 0.1)]
    assert evaluate(ds, good, min_px=0).accuracy == 100.0  # order of estimates does not matter
    # two estimates at the same instance: only one can match
    dup = [Estimate(0, 0, 15, 0.9, g1.R, g1.t, 0.1), Estimate(0, 0, 15, 0.8, g1.R, g1.t, 0.1)]
    r = evaluate(ds, dup, min_px=0)
    assert (r.n_gt, r.n_correct) == (2, 1)
    # a zero-score estimate is "no estimate"; a top-scoring wrong one takes the only slot
    far = Estimate(0, 0, 15, 0.99, g0.R, g0.t + 1.0, 0.1)
    r = evaluate(
        ds, [far, Estimate(0, 0, 15, 0.5, g0.R, g0.t, 0.1), Estimate(0, 0, 15, 0.4, g1.R, g1.t, 0.1)], min_px=0
    )
    assert r.n_correct == 1
    # min_px drops the small instance
    r = evaluate(ds, good, min_px=max(g0.px_visib, g1.px_visib))
    assert r.n_gt == 1
    with pytest.raises(EvaluationError, match="not in"):
        evaluate(ds, [Estimate(9, 99, 15, 1.0, np.eye(3), np.zeros(3), 0.1)])


def test_unusable_instances_get_score_zero(syn, tmp_path):
    pred = tmp_path / "pred"
    pred.mkdir()
    s = open_dataset(syn)[1]
    m = s.instances[0].mask
    empty = np.zeros_like(m)
    np.savez(pred / f"{s.scene_id}_{s.im_id}.npz", masks=np.stack([m, empty, m]), labels=np.array([15, 15, 99]),
             scores=np.array([0.9, 0.8, 0.7]))
    dets = read_predictions(pred, s.scene_id, s.im_id)
    assert [(d.obj_id, d.score) for d in dets] == [
        (15, pytest.approx(0.9)),
        (15, pytest.approx(0.8)),
        (99, pytest.approx(0.7)),
    ]
    assert read_predictions(pred, 0, 0) == []  # no file: no detections
    rows = run_registration(syn, "super4pcs", masks=str(pred), workers=1, progress=False, indices=[1])
    assert len(rows) == 3
    assert rows[0].score > 0 and rows[0].reason == ""
    assert rows[1].score == 0 and "valid depth points" in rows[1].reason
    assert rows[2].score == 0 and "no model" in rows[2].reason
    (pred / "0_0.npz").write_bytes(b"junk")
    with pytest.raises(PredictionError, match="0_0.npz"):
        read_predictions(pred, 0, 0)


def test_unreadable_images_and_models_are_skipped_and_recorded(syn, tmp_path, capsys):
    """Inside a run, an image whose predictions (or files) cannot be read is logged, listed in
    ``<out>_skipped_images.csv`` and skipped; an unreadable model fails its instances with score 0;
    the other images are still registered and the command exits 0."""
    import shutil

    pred = tmp_path / "pred"
    pred.mkdir()
    ds = open_dataset(syn)
    s0, s1 = ds[0], ds[1]
    m = s1.instances[0].mask
    np.savez(pred / f"{s1.scene_id}_{s1.im_id}.npz", masks=m[None], labels=np.array([s1.instances[0].obj_id]),
             scores=np.array([0.9]))
    (pred / f"{s0.scene_id}_{s0.im_id}.npz").write_bytes(b"not an npz")
    out = tmp_path / "r.csv"
    assert _register(syn, "ransac", "--masks", str(pred), "--limit", "2", "--workers", "1", "--no-progress",
                     "--out", str(out)) == 0
    printed = capsys.readouterr().out
    assert "1 unreadable image(s) skipped" in printed
    skipped = (tmp_path / "r_skipped_images.csv").read_text()
    assert f"{s0.scene_id},{s0.im_id}," in skipped and "not an npz" not in skipped and ".npz" in skipped
    assert len(out.read_text().strip().splitlines()) == 2  # header + image 1's estimate
    # a corrupt model file: its instances get score 0 with the reason, the run goes on
    bad = tmp_path / "bad"
    shutil.copytree(syn, bad)
    for f in (bad / "models").glob("*.ply"):
        f.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n")
    fails: list = []
    rows = run_registration(bad, "ransac", workers=1, progress=False, limit=1, failures=fails)
    assert rows and all(r.score == 0 and "model" in r.reason for r in rows)
    assert fails == []
    # a corrupt depth file with GT masks (even the first image): skipped and named, the rest registered
    bad2 = tmp_path / "bad2"
    shutil.copytree(syn, bad2)
    first = sorted((bad2 / "depth").iterdir())[0]
    first.write_bytes(b"junk")
    fails = []
    rows = run_registration(bad2, "ransac", workers=1, progress=False, failures=fails)
    assert len(fails) == 1 and first.name in fails[0][2]
    assert rows and all(r.score > 0 for r in rows)


def test_register_cli_errors(syn, tmp_path, capsys):
    out = str(tmp_path / "x.csv")
    assert _register(tmp_path / "none", "fgr", "--out", out) == 2
    assert _register(syn, "fgr", "--masks", str(tmp_path / "nodir"), "--out", out) == 2
    assert _register(syn, "fgr", "--set", "nope=1", "--out", out) == 2
    err = capsys.readouterr().err
    assert "predicted-mask directory not found" in err and "nope" in err
    assert not (tmp_path / "x.csv").exists()


@pytest.mark.slow
def test_two_workers_match_one(syn, tmp_path):
    # without Super4PCS's wall-clock limit the result cannot depend on how busy the machine is
    cfg = get_preset("default", s4pcs_max_time=None)
    a = run_registration(syn, "super4pcs", cfg=cfg, workers=1, progress=False)
    b = run_registration(syn, "super4pcs", cfg=cfg, workers=2, progress=False)
    assert [(r.scene_id, r.im_id, r.obj_id) for r in a] == [(r.scene_id, r.im_id, r.obj_id) for r in b]
    for ra, rb in zip(a, b, strict=True):
        np.testing.assert_allclose(ra.R, rb.R, atol=1e-9)


@needs_ycbv
@pytest.mark.slow
def test_real_depth_ycbv_every_method(tmp_path):
    """Every method on real Kinect depth (ycbv_sample, GT masks, 2 images): ADD-S within 10 % for most."""
    from sixdpose.evaluation.metrics import adds

    ds = open_dataset(YCBV, split="train_real")
    cache = ReferenceCache(ds)
    cfg = get_preset("default")
    for method in ("ransac", "fgr", "super4pcs"):
        ok = n = 0
        for i in (0, 25):
            s = ds[i]
            for inst in s.instances:
                pts, _, _ = backproject(s.depth, s.K, inst.mask)
                est = estimate_pose(pts, inst.obj_id, method, cache, cfg, icp=True)
                m = ds.model(inst.obj_id)
                ok += adds(est.X_CO[:3, :3], est.X_CO[:3, 3], inst.R, inst.t, m.points) < 0.1 * m.diameter
                n += 1
        assert ok >= n - 2, (method, ok, n)


@needs_ycbv
def test_verify_retries_a_poorly_fitting_pose_and_keeps_the_best():
    """With ``--verify``, an instance whose verified score stays below ``verify_retry_below`` is registered
    again with the global method reseeded (at most ``verify_retries`` times); the best verified pose is
    kept, so the score never drops; ``verify_retry_below=0`` never retries."""
    from sixdpose.registration.hypotheses import Frame

    ds = open_dataset(YCBV, split="train_real")
    s = ds[0]
    inst = s.instances[0]
    pts, _, _ = backproject(s.depth, s.K, inst.mask)
    frame = Frame(s.depth, s.K, inst.mask, s.rgb)
    cache = ReferenceCache(ds)
    never = get_preset("default", verify=True, verify_retry_below=0.0)
    off = estimate_pose(pts, inst.obj_id, "super4pcs", cache, never, icp=True, frame=frame)
    assert "verify_retries" not in off.info
    always = get_preset("default", verify=True, verify_retry_below=1.0, verify_retries=2)  # every score is below 1
    on = estimate_pose(pts, inst.obj_id, "super4pcs", cache, always, icp=True, frame=frame)
    assert on.info["verify_retries"] == 2 and on.score >= off.score - 1e-9 and on.time > 0
    assert get_preset("default").verify_retry_below > 0  # on by default with --verify


@pytest.mark.parametrize("args, verify", [
    ([], True),  # the default profile verifies ...
    (["--no-verify"], False),  # ... unless told not to
    (["--set", "verify=false"], False),
    (["--set", "verify=false", "--verify"], True),  # the flag wins over --set
    (["--profile", "paper"], False),  # the paper's methods are unverified
    (["--profile", "paper", "--verify"], True),
    (["--profile", "fast"], True),  # the fast preset exists for verification
])
def test_register_verifies_by_default(syn, tmp_path, args, verify):
    """``register`` runs the hypothesis verification with ``--profile default`` unless ``--no-verify`` (or
    ``--set verify=false``) says otherwise, not with ``--profile paper`` unless ``--verify``; the choice is
    recorded in ``<out>.config.yml``, and the default run's estimates are exactly ``--verify``'s."""
    import yaml

    out = tmp_path / "r.csv"
    assert _register(syn, "fgr", "--icp", "--limit", "1", "--workers", "1", "--no-progress", "--out", str(out),
                     *args) == 0
    saved = yaml.safe_load(out.with_name("r.config.yml").read_text())
    assert saved["verify"] is verify
    # fast = default with fewer RANSAC iterations, and nothing else
    assert saved["ransac_max_iteration"] == (20000 if "fast" in args else 100000 if "paper" in args else 50000)
    if not args:
        ref = tmp_path / "on.csv"
        assert _register(syn, "fgr", "--icp", "--limit", "1", "--workers", "1", "--no-progress", "--verify",
                         "--out", str(ref)) == 0
        assert results_without_time(out) == results_without_time(ref)
