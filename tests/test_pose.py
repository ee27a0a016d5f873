"""Tests of the learned pose stage (sixdpose.pose). Fast: tiny networks on a 160x120 rendered dataset;
the smoke run (about 30 s on one core) is trained once per module."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import torch

sys.path.insert(0, str(Path(__file__).parent))
from sixdpose.cli import main  # noqa: E402
from sixdpose.pose import checkpoint as ck  # noqa: E402
from sixdpose.pose.config import PoseConfig, RefinerConfig, profile_config  # noqa: E402
from sixdpose.pose.geometry import compose_refinement, quaternion_to_matrix, sixd_to_matrix, to_object_frame  # noqa: E402
from sixdpose.pose.loss import pose_loss  # noqa: E402
from sixdpose.pose.model import OFFSET_SCALE, PoseNet, PSPNet, Refiner, build_posenet  # noqa: E402
from sixdpose.runs import save_checkpoint  # noqa: E402
from test_reg_helpers import H_SMALL, K_SMALL, W_SMALL, make_shape, render_depth  # noqa: E402

torch.set_num_threads(1)
OID = 15


def write_pose_dataset(root: Path, n_images: int = 3, max_deg: float = 60.0, seed: int = 0) -> Path:
    """Like ``write_synthetic_dataset`` (one asymmetric object, 160x120, two instances in the first
    image) with rotations of 10-``max_deg`` degrees from the identity, so a tiny network overfits it fast."""
    from scipy.spatial.transform import Rotation

    from sixdpose.datasets.layout import write_dataset

    name = "035_power_drill"
    P, N, C, diam = make_shape(0.002, seed)
    Pd, Nd, _, _ = make_shape(0.0012, seed)
    rng = np.random.default_rng(seed)
    images = []
    for im in range(n_images):
        poses = []
        for t in ([(-0.09, 0.0, 0.6), (0.09, 0.02, 0.6)] if im == 0 else [(0.0, 0.0, 0.55)]):
            rv = rng.normal(size=3)
            rv *= np.deg2rad(rng.uniform(10, max_deg)) / np.linalg.norm(rv)
            poses.append((Rotation.from_rotvec(rv).as_matrix(), np.asarray(t)))
        depth, label = render_depth([(Pd, Nd, R, t) for R, t in poses])
        rgb = np.zeros((H_SMALL, W_SMALL, 3), np.uint8)
        rgb[label >= 0] = (200, 120, 40)
        insts = [
            {"obj_name": name, "obj_id": OID, "inst": k, "R": R, "t": t, "mask": label == k}
            for k, (R, t) in enumerate(poses)
        ]
        images.append({"im_id": im, "scene_id": im % 2, "K": K_SMALL, "rgb": rgb, "depth": depth, "instances": insts})
    models = {name: {"obj_id": OID, "diameter": diam, "symmetric": False, "points": P, "normals": N, "colors": C}}
    return write_dataset(root, images, models, {"generator": "tests.test_pose"})


@pytest.fixture(scope="module")
def pose_ds(tmp_path_factory) -> Path:
    return write_pose_dataset(tmp_path_factory.mktemp("pose") / "ds")


@pytest.fixture(scope="module")
def smoke_run(pose_ds, tmp_path_factory) -> Path:
    run = tmp_path_factory.mktemp("poserun") / "run"
    assert main(["train-pose", "--data", str(pose_ds), "--out", str(run), "--profile", "smoke", "--no-progress"]) == 0
    return run


def fake_pose_run(path: Path, cfg: PoseConfig, classes=((OID, "035_power_drill", False),)) -> Path:
    """A finished pose run with random weights (no training)."""
    torch.manual_seed(0)
    net = build_posenet(cfg, len(classes))
    path.mkdir(parents=True, exist_ok=True)
    save_checkpoint(
        ck.weights("pose", cfg, classes, net.state_dict(), epoch=1),
        path / ck.FINAL,
    )
    return path


# ---------------------------------------------------------------- blocks
@pytest.mark.parametrize("colour", [False, True])
def test_local_geometry_without_edge_tensors_is_the_edge_convolution(colour):
    """LocalGeometry's edge convolutions computed per point and gathered (_edge_conv) give what the 1x1
    convolutions over the built edge tensors [f_i, s (f_j - f_i)] (DGCNN's EdgeConv, _edges) give."""
    from sixdpose.pose.model import LocalGeometry

    torch.manual_seed(0)
    m = LocalGeometry(32, width=0.5, norm="group", colour=colour).eval()
    cloud, cols = torch.randn(3, 40, 3), torch.randn(3, 3, 40)
    with torch.no_grad():
        got = m(cloud, cols if colour else None)
        x, idx = cloud.transpose(1, 2), torch.cdist(cloud, cloud).topk(16, dim=2, largest=False).indices
        e = m._edges(x, idx, 5.0)
        e = torch.cat([e, m._edges(cols, idx)], 1) if colour else e
        f1 = m.edge1(e).max(dim=3).values
        ref = m.out(torch.cat([f1, m.edge2(m._edges(f1, idx)).max(dim=3).values], 1))
    assert got.shape == (3, 32, 40) and torch.allclose(got, ref, atol=1e-5) and ref.abs().max() > 0.5


def test_heads_computed_without_repeating_the_global_feature_are_the_concatenated_ones():
    """PoseNet._head (the global feature's product once per instance) and the dense head's per-class output
    rows give what the DenseFusion formulation (the global feature repeated at every point, every class's
    outputs) gives."""
    torch.manual_seed(0)
    for head in ("paper", "dense"):
        net = PoseNet(4, width=0.25, norm="group", head=head, flips=3 if head == "dense" else 0).eval()
        cloud, emb, obj = torch.randn(3, 30, 3), torch.randn(3, 32, 30), torch.tensor([2, 0, 2])
        with torch.no_grad():
            seq = net.head_d if head == "dense" else net.head_t
            split, full = net._head(seq, *net._fused(cloud, emb)), seq(net.fuse(cloud, emb))
            assert torch.allclose(split, full, atol=1e-5) and full.abs().max() > 0.1
            if head == "dense":
                out = net._dense(cloud, emb, obj)
                every = net.out_d(full).view(3, 4, 7, 30)[torch.arange(3), obj]
                assert torch.allclose(out["conf_logit"], every[:, 3], atol=1e-5)
                coords = net.centres[obj][:, None, :] + OFFSET_SCALE * every[:, :3].transpose(1, 2)
                assert torch.allclose(out["coords"], coords, atol=1e-5)


def test_block_shapes_and_1408_fusion():
    x = torch.randn(2, 3, 64, 48)
    assert PSPNet(width=1 / 16, emb_dim=32)(x).shape == (2, 32, 64, 48)
    net = PoseNet(3, width=1.0)
    assert net.fused_channels == 1408
    cloud, emb = torch.randn(2, 20, 3), torch.randn(2, 32, 20)
    assert net.fuse(cloud, emb).shape == (2, 1408, 20)
    small = PoseNet(3, width=1 / 16)
    imgs = torch.randn(2, 3, 32, 32)
    out = small(
        imgs,
        torch.tensor([0, 1, 1]),
        torch.randint(0, 32 * 32, (3, 20)),
        torch.randn(3, 20, 3),
        torch.tensor([0, 2, 1]),
    )
    assert out["R"].shape == (3, 3, 3) and out["t"].shape == (3, 3) and out["emb"].shape == (3, 32, 20)
    assert torch.allclose(out["R"] @ out["R"].transpose(1, 2), torch.eye(3).expand(3, 3, 3), atol=1e-5)
    ref = Refiner(3, width=1.0)
    assert ref.conv5[0].in_channels == 384 and ref.conv6[0].out_channels == 1024
    R, t = ref(torch.randn(3, 20, 3), torch.randn(3, 32, 20), torch.tensor([0, 1, 2]))
    assert R.shape == (3, 3, 3) and t.shape == (3, 3)
    assert not any(
        isinstance(m, (torch.nn.BatchNorm2d, torch.nn.GroupNorm, torch.nn.BatchNorm1d)) for m in net.modules()
    )
    assert any(isinstance(m, torch.nn.GroupNorm) for m in PoseNet(1, width=1 / 16, norm="group").modules())


def test_attention_pooling_sums_to_one():
    net = PoseNet(1, width=1 / 16)
    out = net(torch.randn(1, 3, 32, 32), torch.tensor([0, 0]), torch.randint(0, 1024, (2, 30)), torch.randn(2, 30, 3),
              torch.tensor([0, 0]))
    for w in (out["att_r"], out["att_t"]):
        assert w.shape == (2, 30) and (w >= 0).all()
        assert torch.allclose(w.sum(1), torch.ones(2), atol=1e-6)


def test_loss_equals_brute_force_add_and_chamfer():
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(0)
    n, m = 3, 40
    pts = rng.normal(size=(n, m, 3)) * 0.05
    Rg, Rp = Rotation.random(n, random_state=1).as_matrix(), Rotation.random(n, random_state=2).as_matrix()
    tg, tp = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    sym = np.array([False, True, False])
    T = lambda a: torch.from_numpy(np.asarray(a))  # noqa: E731
    got = pose_loss(T(Rp), T(tp), T(Rg), T(tg), T(pts), T(sym)).numpy()
    for i in range(n):
        g = pts[i] @ Rg[i].T + tg[i]
        p = pts[i] @ Rp[i].T + tp[i]
        if sym[i]:
            want = np.mean([min(np.linalg.norm(g[j] - p[k]) for k in range(m)) for j in range(m)])
        else:
            want = np.mean([np.linalg.norm(g[j] - p[j]) for j in range(m)])
        assert got[i] == pytest.approx(want, rel=1e-9)


def test_quaternion_and_6d_give_rotations():
    from scipy.spatial.transform import Rotation

    q = torch.randn(50, 4, dtype=torch.float64) * 3
    R = quaternion_to_matrix(q)
    want = Rotation.from_quat(q[:, [1, 2, 3, 0]].numpy()).as_matrix()  # scipy: (x, y, z, w)
    assert np.allclose(R.numpy(), want, atol=1e-12)
    R6 = sixd_to_matrix(torch.randn(50, 6, dtype=torch.float64))
    eye = torch.eye(3, dtype=torch.float64).expand(50, 3, 3)
    assert torch.allclose(R6 @ R6.transpose(1, 2), eye, atol=1e-12) and torch.allclose(
        torch.linalg.det(R6), torch.ones(50, dtype=torch.float64)
    )
    Rt = torch.from_numpy(Rotation.random(5, random_state=0).as_matrix())
    assert torch.allclose(sixd_to_matrix(torch.cat([Rt[:, :, 0], Rt[:, :, 1]], 1)), Rt, atol=1e-12)


def test_refiner_composition_recovers_pose():
    from scipy.spatial.transform import Rotation

    R_true = torch.from_numpy(Rotation.random(4, random_state=3).as_matrix())
    t_true = torch.randn(4, 3, dtype=torch.float64)
    R_cur = torch.from_numpy(Rotation.random(4, random_state=4).as_matrix())
    t_cur = torch.randn(4, 3, dtype=torch.float64)
    # the refiner sees the cloud in the estimated object frame: the model under the residual pose
    x = torch.randn(4, 30, 3, dtype=torch.float64)
    cloud_C = x @ R_true.transpose(1, 2) + t_true[:, None]
    cloud_O = to_object_frame(cloud_C, R_cur, t_cur)
    R_d = R_cur.transpose(1, 2) @ R_true
    t_d = (R_cur.transpose(1, 2) @ (t_true - t_cur)[:, :, None])[:, :, 0]
    assert torch.allclose(cloud_O, x @ R_d.transpose(1, 2) + t_d[:, None], atol=1e-12)
    R, t = compose_refinement(R_cur, t_cur, R_d, t_d)
    assert torch.allclose(R, R_true, atol=1e-12) and torch.allclose(t, t_true, atol=1e-12)


@pytest.mark.parametrize("crop", [32, 0])
def test_batched_inference_equals_per_instance(pose_ds, crop):
    from sixdpose.datasets import as_reader
    from sixdpose.pose.data import Frame, collate_frames, extract_instance
    from sixdpose.pose.infer import run_networks

    cfg = profile_config("smoke", {"crop": crop})
    torch.manual_seed(0)
    net = build_posenet(cfg, 1).eval()
    s = as_reader(pose_ds).load((0, 0))
    rng = np.random.default_rng(0)
    insts = [
        extract_instance(
            s.rgb, s.depth, s.K, g.mask, g.obj_id, crop=crop, margin=0.1, num_points=64, min_points=10, rng=rng, index=k
        )
        for k, g in enumerate(s.instances)
    ]
    img = None if crop else s.rgb
    Rb, tb = run_networks(net, None, collate_frames([Frame(img, insts)], {OID: 0}), 0, "cpu")
    for k, inst in enumerate(insts):
        R1, t1 = run_networks(net, None, collate_frames([Frame(img, [inst])], {OID: 0}), 0, "cpu")
        assert np.allclose(Rb[k], R1[0], atol=1e-5) and np.allclose(tb[k], t1[0], atol=1e-6)


@pytest.mark.parametrize("appearance", ["local", "none"])
def test_a_network_that_reads_no_image_is_given_no_crops(pose_ds, appearance):
    """A network whose appearance reads no image (local geometry, or none) gives the same outputs without the
    instances' crops (extract_instance(with_image=False), collate_frames' empty images) as with them, from the same
    points; a CNN's and a colour-reading local network do read them."""
    from sixdpose.datasets import as_reader
    from sixdpose.pose.data import Frame, collate_frames, extract_instance

    assert PoseNet(2, width=1 / 16, appearance="cnn").reads_images
    assert PoseNet(2, width=1 / 16, head="dense", appearance="local_rgb").reads_images
    torch.manual_seed(0)
    net = PoseNet(1, width=1 / 16, head="dense", flips=2, appearance=appearance, input_frame="pca").eval()
    assert not net.reads_images
    s = as_reader(pose_ds).load((0, 0))
    outs = []
    for image in (True, False):
        rng = np.random.default_rng(0)
        insts = [extract_instance(s.rgb, s.depth, s.K, g.mask, g.obj_id, crop=32, margin=0.1, num_points=64,
                                  min_points=10, rng=rng, index=k, with_image=image)
                 for k, g in enumerate(s.instances)]
        b = collate_frames([Frame(None, insts)], {OID: 0})
        assert (b["images"].shape[0] == 0) == (not image) and (insts[0].image is None) == (not image)
        with torch.no_grad():
            outs.append((b["cloud"], net(b["images"], b["img_index"], b["choose"], b["cloud"], b["obj_index"])))
    (c1, o1), (c2, o2) = outs
    assert torch.equal(c1, c2)
    assert torch.equal(o1["coords"], o2["coords"]) and torch.equal(o1["conf_logit"], o2["conf_logit"])


def test_depth_band_drops_background_seen_through_a_loose_mask():
    """A predicted mask spilling onto the background: the depth band (the object's diameter) keeps the
    object's points only, so the cloud's centroid stays on the object; 0 keeps everything."""
    from sixdpose.pose.data import extract_instance

    H, W = 60, 80
    K = np.array([[100.0, 0, 40], [0, 100.0, 30], [0, 0, 1]])
    depth = np.full((H, W), 1.5)
    depth[20:40, 30:50] = 0.6 + 0.001 * np.arange(20)[None, :]  # the object, 2 cm of depth relief
    mask = np.zeros((H, W), bool)
    mask[18:42, 28:52] = True  # a 2-pixel spill: 176 background pixels around 400 object pixels
    rgb = np.zeros((H, W, 3), np.uint8)
    args = dict(crop=16, margin=0.1, num_points=32, min_points=10, rng=np.random.default_rng(0))
    loose = extract_instance(rgb, depth, K, mask, 1, **args)
    banded = extract_instance(rgb, depth, K, mask, 1, depth_band=0.1, **args)
    assert loose.n_valid == 576 and banded.n_valid == 400
    assert np.all(np.abs(banded.cloud[:, 2] - 0.61) < 0.02)
    gt = depth[20:40, 30:50] > 0
    exact = np.zeros((H, W), bool)
    exact[20:40, 30:50] = gt
    assert extract_instance(rgb, depth, K, exact, 1, depth_band=0.1, **args).n_valid == 400


def test_configs_documented_and_validated():
    from sixdpose.config import undocumented_fields
    from sixdpose.errors import ConfigError

    assert undocumented_fields(PoseConfig) == []
    assert undocumented_fields(RefinerConfig) == []
    for bad in ({"crop": 30}, {"translation": "x"}, {"rotation": "euler"}, {"norm": "layer"}, {"width": 0}):
        with pytest.raises(ConfigError):
            profile_config("smoke", bad)


# ---------------------------------------------------------------- training, CLI
@pytest.mark.slow
def test_smoke_overfits_and_predict_pose_csv_is_scored(smoke_run, pose_ds, tmp_path):
    from sixdpose.artifacts.poses import read_results
    from sixdpose.evaluation.evaluate import evaluate

    out = tmp_path / "res.csv"
    assert (
        main(["predict-pose", "--data", str(pose_ds), "--pose", str(smoke_run), "--out", str(out), "--no-progress"])
        == 0
    )
    assert (tmp_path / "res.config.yml").is_file()
    rows = read_results(out)
    assert len(rows) == 4 and all(r.score > 0 for r in rows)
    res = evaluate(pose_ds, rows, min_px=0)
    assert res.n_gt == 4 and res.accuracy >= 90.0, res.records
    for name in ("config.json", "run.json", "metrics.csv", "last.pt", "model.pt"):
        assert (smoke_run / name).is_file()


def test_resume_is_bit_identical(pose_ds, tmp_path):
    from sixdpose.pose.train import train_pose

    ov = dict(epochs=2, repeat=1, batch_size=2)
    train_pose(pose_ds, tmp_path / "a", profile="smoke", progress=False, **ov)
    train_pose(pose_ds, tmp_path / "b", profile="smoke", progress=False, **dict(ov, epochs=1))
    s = train_pose(pose_ds, tmp_path / "b", resume=True, progress=False, epochs=2)
    assert s["start_epoch"] == 1 and s["epochs"] == 2
    a, b = ck.load(tmp_path / "a" / ck.LAST), ck.load(tmp_path / "b" / ck.LAST)
    assert a["global_step"] == b["global_step"]
    for k in a["model"]:
        assert torch.equal(a["model"][k], b["model"][k]), k
    for k in a["optimizer"]["state"]:
        assert all(
            torch.equal(a["optimizer"]["state"][k][n], b["optimizer"]["state"][k][n]) for n in ("exp_avg", "exp_avg_sq")
        )


def test_time_budget_stops_cleanly(pose_ds, tmp_path):
    from sixdpose.pose.train import read_metrics, train_pose

    s = train_pose(pose_ds, tmp_path / "r", profile="smoke", progress=False, epochs=5, repeat=4, time_budget=1e-6)
    assert s["stopped_early"] and s["epochs"] == 1
    assert s["steps"] == 1  # checked after every step: the other 3 steps of the epoch are skipped
    assert ck.load(tmp_path / "r")["epoch"] == 1
    assert read_metrics(tmp_path / "r")[-1]["epoch"] == 0


@pytest.mark.slow  # uses the trained smoke network
def test_train_refiner_predict_and_mismatch(smoke_run, pose_ds, tmp_path, capsys):
    ref = tmp_path / "ref"
    assert (
        main(
            [
                "train-refiner",
                "--pose",
                str(smoke_run),
                "--data",
                str(pose_ds),
                "--out",
                str(ref),
                "--profile",
                "smoke",
                "--val",
                str(pose_ds),
                "--no-progress",
                "--set",
                "epochs=1",
            ]
        )
        == 0
    )
    from sixdpose.pose.train import read_metrics

    assert read_metrics(ref)[-1]["val_add"] is not None
    out = tmp_path / "r.csv"
    assert (
        main(
            [
                "predict-pose",
                "--data",
                str(pose_ds),
                "--pose",
                str(smoke_run),
                "--refiner",
                str(ref),
                "--iterations",
                "2",
                "--out",
                str(out),
                "--no-progress",
            ]
        )
        == 0
    )
    other = fake_pose_run(tmp_path / "other", profile_config("smoke", {"width": 0.125}))
    capsys.readouterr()
    assert (
        main(["predict-pose", "--data", str(pose_ds), "--pose", str(other), "--refiner", str(ref), "--out", str(out)])
        == 2
    )
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "architecture" in err
    assert (
        main(
            [
                "train-refiner",
                "--pose",
                str(other),
                "--data",
                str(pose_ds),
                "--out",
                str(ref),
                "--resume",
                "--epochs",
                "2",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "does not match" in err


def test_corrupt_checkpoint_one_line_exit_2(pose_ds, tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.pt").write_bytes(b"not a checkpoint")
    assert main(["predict-pose", "--data", str(pose_ds), "--pose", str(run), "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "corrupt" in err and "model.pt" in err
    assert not (tmp_path / "x.csv").exists()


def test_checkpoint_helpers_write_what_load_and_the_refiner_check_accept(tmp_path):
    from sixdpose.pose.config import refiner_profile_config
    from sixdpose.pose.model import build_refiner

    cfg, rcfg = profile_config("smoke"), refiner_profile_config("smoke")
    cls = [[OID, "035_power_drill", False]]
    run = fake_pose_run(tmp_path / "p", cfg, classes=[tuple(c) for c in cls])
    pose = ck.load(run, kind="pose")
    assert pose["classes"] == cls and pose["epoch"] == 1 and pose["arch"] == cfg.arch()
    ref = build_refiner(rcfg, 1, cfg.emb_dim)
    link = ck.pose_link(pose)
    assert link == {"classes": cls, "arch": cfg.arch(), "run": str(run / ck.FINAL)}
    save_checkpoint(ck.weights("refiner", rcfg, cls, ref.state_dict(), pose=link), tmp_path / "ref.pt")
    refiner = ck.load(tmp_path / "ref.pt", kind="refiner")
    assert refiner["pose"] == link
    ck.check_refiner_matches(refiner, pose)  # no error: the link names this pose run
    with pytest.raises(ValueError, match="pass run="):
        ck.pose_link({"classes": cls, "arch": cfg.arch()})
    with pytest.raises(ValueError, match="refiner checkpoint needs"):
        ck.header("refiner", rcfg, cls)
    with pytest.raises(ValueError, match="kind must be"):
        ck.header("seg", cfg, cls)


def test_cli_refuses_foreign_output(pose_ds, tmp_path, capsys):
    out = tmp_path / "busy"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert main(["train-pose", "--data", str(pose_ds), "--out", str(out)]) == 2
    assert "not empty" in capsys.readouterr().err
    foreign = tmp_path / "f.csv"
    foreign.write_text("a,b\n")
    run = fake_pose_run(tmp_path / "p", profile_config("smoke"))
    assert main(["predict-pose", "--data", str(pose_ds), "--pose", str(run), "--out", str(foreign)]) == 2
    assert foreign.read_text() == "a,b\n"


def test_score0_rows_for_few_points_unknown_ids_and_nan_depth(pose_ds, tmp_path):
    from sixdpose.artifacts.predictions import Detection
    from sixdpose.datasets import as_reader
    from sixdpose.pose.infer import Estimator

    run = fake_pose_run(tmp_path / "p", profile_config("smoke"))
    est = Estimator(run, device="cpu")
    s = as_reader(pose_ds).load((0, 0))
    m0, m1 = s.instances[0].mask, s.instances[1].mask
    s.depth = s.depth.copy()
    v, u = np.nonzero(m1)
    s.depth[v[5:], u[5:]] = np.nan  # 5 valid pixels left, the rest NaN
    dets = [Detection(OID, 0.9, m0), Detection(OID, 0.8, m1), Detection(99, 0.7, m0)]
    rows = est.predict(s, dets)
    assert [r.obj_id for r in rows] == [OID, OID, 99]
    assert rows[0].score == pytest.approx(0.9) and np.isfinite(rows[0].t).all()
    assert rows[1].score == 0 and "5 valid depth" in rows[1].reason
    assert rows[2].score == 0 and "not a class" in rows[2].reason
    assert len({r.time for r in rows}) == 1 and rows[0].time > 0


@pytest.mark.slow  # uses the trained smoke network
def test_icp_colour_rows_and_predicted_masks(smoke_run, pose_ds, tmp_path):
    from sixdpose.artifacts.poses import read_results
    from sixdpose.artifacts.predictions import write_predictions
    from sixdpose.datasets import as_reader
    from sixdpose.evaluation.evaluate import evaluate

    reader = as_reader(pose_ds)
    pred = tmp_path / "pred"
    for key in reader.keys():  # noqa: SIM118 (a dataset reader's keys(), not a dict)
        s = reader.load(key)
        masks = np.stack([g.mask for g in s.instances])
        write_predictions(pred, *key, masks, [g.obj_id for g in s.instances], np.full(len(masks), 0.9))
    out = tmp_path / "icp.csv"
    assert main(["predict-pose", "--data", str(pose_ds), "--pose", str(smoke_run), "--masks", str(pred), "--icp",
                 "--colour-verify", "--out", str(out), "--no-progress"]) == 0
    rows = read_results(out)
    assert len(rows) == 4 and all(r.score == pytest.approx(0.9) for r in rows)
    assert evaluate(reader, rows, min_px=0).accuracy >= 75.0
    # the hybrid stage's hypothesis verification after the network (predict-pose --verify)
    out_v = tmp_path / "verify.csv"
    assert main(["predict-pose", "--data", str(pose_ds), "--pose", str(smoke_run), "--masks", str(pred), "--icp",
                 "--colour-verify", "--verify", "--out", str(out_v), "--no-progress"]) == 0
    rows_v = read_results(out_v)
    assert evaluate(reader, rows_v, min_px=0).accuracy >= 75.0
    assert "verify: true" in out_v.with_name("verify.config.yml").read_text()
    # the score is the verification's (as register --verify writes it), no longer the detection's 0.9
    assert all(0 < r.score <= 1 for r in rows_v) and any(r.score != pytest.approx(0.9) for r in rows_v)
    (pred / "0_0.npz").write_bytes(b"")  # an empty prediction file: one line naming it
    assert (
        main(
            ["predict-pose", "--data", str(pose_ds), "--pose", str(smoke_run), "--masks", str(pred), "--out", str(out)]
        )
        == 2
    )


@pytest.mark.parametrize(
    "ov", [{"translation": "centroid_offset", "rotation": "6d"}, {"norm": "group"}, {"norm": "batch"}, {"crop": 0}]
)
def test_ablation_options_train_and_predict(pose_ds, tmp_path, ov):
    from sixdpose.pose.infer import predict_dataset
    from sixdpose.pose.train import train_pose

    s = train_pose(pose_ds, tmp_path / "r", profile="smoke", progress=False, epochs=1, repeat=1, **ov)
    assert np.isfinite(s["last_loss"])
    rows, _ = predict_dataset(pose_ds, tmp_path / "r")
    assert len(rows) == 4 and all(r.score > 0 and np.isfinite(r.t).all() for r in rows)


@pytest.mark.slow
def test_ddp_two_processes_gloo(pose_ds, tmp_path):
    import os
    import shutil
    import subprocess

    torchrun = Path(sys.executable).with_name("torchrun")
    if not torchrun.exists() and not shutil.which("torchrun"):
        pytest.skip("torchrun not installed")
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(Path(__file__).parents[1] / "src"))
    run = tmp_path / "ddp"
    p = subprocess.run(
        [
            str(torchrun if torchrun.exists() else "torchrun"),
            "--nproc_per_node",
            "2",
            "--master_port",
            "29517",
            "-m",
            "sixdpose.cli",
            "train-pose",
            "--data",
            str(pose_ds),
            "--out",
            str(run),
            "--profile",
            "smoke",
            "--set",
            "epochs=2",
            "--set",
            "repeat=2",
            "--no-progress",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert p.returncode == 0, p.stderr[-2000:]
    c = ck.load(run / ck.LAST)
    assert c["world_size"] == 2 and len(c["rng"]) == 2 and c["epoch"] == 2


def test_ablation_trains_each_variant_and_scores_on_val(pose_ds, tmp_path):
    from sixdpose.pose.ablation import COLUMNS, run_ablation

    variants = {
        "paper": {"translation": "absolute", "norm": "none"},
        "offset+group": {"translation": "centroid_offset", "norm": "group"},
    }
    t = run_ablation(pose_ds, pose_ds, tmp_path / "abl", profile="smoke", variants=variants, epochs=2, min_px=0)
    assert list(t.columns) == list(COLUMNS) and list(t["variant"]) == ["paper", "offset+group"]
    assert list(t["translation"]) == ["absolute", "centroid_offset"] and list(t["norm"]) == ["none", "group"]
    assert (t["epochs"] == 2).all() and (t["steps"] > 0).all() and (t["n_val"] > 0).all()
    assert t["val_add"].between(0, 100).all()
    runs = sorted(p.name for p in (tmp_path / "abl").iterdir())
    assert runs == ["0_paper", "1_offset_group"]
    # a second call scores the finished runs without training them again
    mtime = (tmp_path / "abl" / "0_paper" / "model.pt").stat().st_mtime_ns
    t2 = run_ablation(pose_ds, pose_ds, tmp_path / "abl", profile="smoke", variants=variants, epochs=2, min_px=0)
    assert (tmp_path / "abl" / "0_paper" / "model.pt").stat().st_mtime_ns == mtime
    assert list(t2["val_add"]) == list(t["val_add"])


def test_pose_ablation_cli(pose_ds, tmp_path, capsys):
    """``sixdpose pose-ablation``: the chosen variants with equal epochs, a table beside the runs and a
    result artifact; a budget is required and bad variant indices are one line."""
    import json

    out, res = tmp_path / "abl", tmp_path / "res"
    base = ["pose-ablation", "--train", str(pose_ds), "--val", str(pose_ds), "--out", str(out), "--profile", "smoke",
            "--epochs", "1", "--min-px", "0", "--no-progress"]
    argv = base + ["--variants", "0,5", "--results-dir", str(res)]
    assert main(argv) == 0
    data = json.loads((res / "pose_ablation_smoke.json").read_text())
    rows = data["rows"]
    assert [r["variant"] for r in rows] == ["paper (absolute t, quaternion, no norm)", "centroid offset + 6D rotation"]
    assert all(r["epochs"] == 1 and r["steps"] > 0 for r in rows)
    assert (out / "ablation.csv").is_file() and (out / "ablation.tex").is_file()
    capsys.readouterr()
    for bad in (["--variants", "9"], ["--variants", "x"]):
        assert main(base + bad + ["--no-result"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--variants" in err[0]
    no_budget = [a for a in argv if a not in ("--epochs", "1")]
    assert main(no_budget) == 2 and "--epochs" in capsys.readouterr().err


def test_colour_jitter_augmentation():
    """colour_jitter: each image of a batch gets its own gain/gamma transform, reproducible from the rng,
    within [0, 1] before normalisation; 0 leaves the colours as they are."""
    from sixdpose.pose.data import MEAN, STD, normalise_images

    imgs = np.random.default_rng(0).integers(0, 256, size=(4, 8, 8, 3), dtype=np.uint8)
    plain = normalise_images(imgs)
    assert torch.equal(normalise_images(imgs, 0.0, np.random.default_rng(1), jitter=0.0), plain)
    a = normalise_images(imgs, 0.0, np.random.default_rng(1), jitter=0.3)
    b = normalise_images(imgs, 0.0, np.random.default_rng(1), jitter=0.3)
    assert torch.equal(a, b) and not torch.equal(a, plain)
    raw = a.numpy().transpose(0, 2, 3, 1) * STD + MEAN  # back to [0, 1] colours
    assert raw.min() >= -1e-5 and raw.max() <= 1 + 1e-5
    x = imgs.astype(np.float32) / 255.0
    ratios = [np.median(raw[k] / np.maximum(x[k], 1e-3)) for k in range(4)]
    assert np.ptp(ratios) > 0.01  # a different transform per image
    with pytest.raises(Exception, match="colour_jitter"):
        PoseConfig(colour_jitter=1.5)


def test_learned_method_in_compare_methods(smoke_run, pose_ds):
    """``compare.learned_method``: a trained run as a method of ``compare_methods``, on chosen images only."""
    from sixdpose.datasets import open_dataset
    from sixdpose.reporting.compare import compare_methods, learned_method

    keys = open_dataset(pose_ds).keys()
    table, runs = compare_methods(pose_ds, {"learned": learned_method(smoke_run)}, {"gt": ("gt", [1, 2])}, min_px=0)
    run = runs[("gt", "learned")]
    assert sorted({(e.scene_id, e.im_id) for e in run.estimates}) == sorted(keys[1:3])
    assert table.loc[0, "n_gt"] == 2 and 0 <= table.loc[0, "add_s"] <= 100
    from sixdpose.reporting.compare import per_object_table

    po = per_object_table(runs)
    assert list(po.columns) == ["obj_id", "name", "n_gt", "learned"] and po.loc[0, "n_gt"] == 2
    assert po.loc[0, "learned"] == table.loc[0, "add_s"]  # one object: its accuracy is the overall one


def test_onboarding_is_timed_apart_from_the_frames(pose_ds, tmp_path):
    """predict-pose --icp --verify: the objects' first-use model-side data (ICP reference, verification
    surface) is their onboarding, spent on the first frame that needs it, left out of that frame's time
    and recorded by ``settings()``; the same frame again spends none."""
    import time

    from sixdpose.datasets import as_reader
    from sixdpose.pose.infer import Estimator

    run = fake_pose_run(tmp_path / "p", profile_config("smoke"))
    reader = as_reader(pose_ds)
    s = reader.load((0, 0))
    est = Estimator(run, device="cpu", icp=True, verify=True, reader=reader)
    t0 = time.perf_counter()
    rows = est.predict(s)
    wall = time.perf_counter() - t0
    first = est.onboarding_s
    assert first > 0 and rows[0].time <= wall - first + 1e-6
    rows = est.predict(s)
    assert est.onboarding_s == first and rows[0].time > 0
    assert est.settings()["onboarding_s"] == round(first, 3)


def test_the_learned_stage_verifies_with_its_slides_and_a_set_wins(pose_ds, tmp_path):
    """predict-pose --verify starts from the default preset with LEARNED_VERIFY (slides along an elongated
    model's axis), records them beside the results, and a ``--set`` of the same field wins."""
    from sixdpose.datasets import as_reader
    from sixdpose.pose.infer import Estimator
    from sixdpose.registration import LEARNED_VERIFY

    run = fake_pose_run(tmp_path / "p", profile_config("smoke"))
    reader = as_reader(pose_ds)
    assert LEARNED_VERIFY["verify_slides"] > 0
    est = Estimator(run, device="cpu", icp=True, verify=True, reader=reader, fallback="ransac")
    for k, v in LEARNED_VERIFY.items():
        assert getattr(est.reg_cfg, k) == v and getattr(est.fallback_cfg, k) == v
        assert est.settings()["verify_config"][k] == v
    # the texture search of a ball's turn: on, but not for the symmetric classes (their turn is not scored)
    assert est._symmetric == {int(c[0]) for c in est.classes if c[2]}
    sym = int(est.classes[0][0])
    other = sym + 1  # not a symmetric class
    est._symmetric = {sym}  # as a checkpoint with a symmetric first class would have it
    for cfg in (est.reg_cfg, est.fallback_cfg):  # the learned pose's verification and the fallback's alike
        assert cfg.verify_texture_lattice > 0
        assert est._for_object(cfg, sym).verify_texture_lattice == 0 and est._for_object(cfg, other) is cfg
        assert est._for_object(cfg, sym) is est._for_object(cfg, sym)  # made once per config
    off = Estimator(run, device="cpu", icp=True, verify=True, reader=reader, overrides={"verify_slides": 0})
    assert off.reg_cfg.verify_slides == 0 and off.settings()["verify_config"]["verify_slides"] == 0


def test_fallback_registers_the_poorly_verified_instances(pose_ds, tmp_path):
    """predict-pose --verify --fallback ransac: an instance whose verified learned pose scores below
    verify_retry_below is registered by RANSAC too and the better-verified pose is kept; at threshold 0 none
    is; without --verify the option is refused."""
    from sixdpose.datasets import as_reader
    from sixdpose.evaluation.evaluate import evaluate
    from sixdpose.pose.infer import Estimator

    run = fake_pose_run(tmp_path / "p", profile_config("smoke"))  # random weights: its poses are wrong
    reader = as_reader(pose_ds)
    s = reader.load((0, 0))

    def predict(**kw):
        est = Estimator(run, device="cpu", icp=True, verify=True, reader=reader, **kw)
        return est.predict(s), est

    alone, _ = predict()
    always, est = predict(fallback="ransac", overrides={"verify_retry_below": 1.0})  # every score is below 1
    assert est.fallback_tried == len(s.instances) and est.fallback_won >= 1
    assert all(b.score >= a.score for a, b in zip(alone, always, strict=True))
    assert evaluate(reader, always, min_px=0).n_correct > evaluate(reader, alone, min_px=0).n_correct
    assert est.settings()["fallback"]["instances_tried"] == len(s.instances)
    assert est.settings()["fallback"]["seed"] == 0  # the preset's; each instance's is derived from it and its ids
    never, est0 = predict(fallback="ransac", overrides={"verify_retry_below": 0.0})
    assert est0.fallback_tried == 0 and [r.score for r in never] == [r.score for r in alone]
    from sixdpose.pose.data import PoseError

    with pytest.raises(PoseError, match="needs --verify"):
        Estimator(run, device="cpu", icp=True, reader=reader, fallback="ransac")
    assert main(["predict-pose", "--data", str(pose_ds), "--pose", str(run), "--masks", "gt", "--fallback", "ransac",
                 "--out", str(tmp_path / "x.csv"), "--no-progress"]) == 2
