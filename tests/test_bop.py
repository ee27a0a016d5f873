"""BOP reader (ycbv_sample with depth and masks, lmo without) and export-bop round trip."""

import json

import numpy as np
import pytest

from sixdpose.cli import main
from sixdpose.datasets import DatasetError, open_dataset
from sixdpose.datasets.bop import BopDataset
from test_reg_helpers import LMO, YCBV, write_synthetic_dataset

needs_ycbv = pytest.mark.skipif(not YCBV.is_dir(), reason="shared/data/ycbv_sample not available")
needs_lmo = pytest.mark.skipif(not LMO.is_dir(), reason="shared/data/lmo not available")


@needs_ycbv
def test_ycbv_sample_reads_in_metres():
    ds = open_dataset(YCBV, split="train_real")
    assert isinstance(ds, BopDataset)
    assert len(ds) == 40 and ds.has_depth and ds.has_masks
    s = ds[0]
    assert (s.scene_id, s.im_id) == ds.keys()[0]
    assert s.rgb.shape == (480, 640, 3) and s.rgb.dtype == np.uint8
    assert s.depth.dtype == np.float32 and 0.3 < np.median(s.depth[s.depth > 0]) < 2.0  # metres
    assert [i.obj_id for i in s.instances] == [8, 14, 21]
    inst = s.instances[0]
    assert inst.mask.dtype == bool and inst.mask.sum() == inst.px_visib
    assert 0.3 < inst.t[2] < 1.5  # mm -> m
    np.testing.assert_allclose(inst.R @ inst.R.T, np.eye(3), atol=1e-5)
    # the object's depth under its mask is close to its translation (metres everywhere)
    assert abs(np.median(s.depth[inst.mask & (s.depth > 0)]) - inst.t[2]) < 0.1
    m = ds.model(8)
    assert m.points.shape[1] == 3 and m.normals is not None
    assert 0.05 < m.diameter < 0.2 and np.ptp(m.points[:, 0]) < m.diameter
    assert m.symmetric is False  # no symmetry annotations in this sample
    assert BopDataset(YCBV, "train_real", symmetric_ids=[21]).model(21).symmetric


@needs_lmo
def test_lmo_without_depth_and_masks():
    ds = open_dataset(LMO, split="test")
    assert len(ds) == 30 and not ds.has_depth and not ds.has_masks
    s = ds[0]
    assert s.depth is None and all(i.mask is None for i in s.instances)
    assert all(i.px_visib >= 0 for i in s.instances)  # from scene_gt_info.json
    assert ds.model(10).symmetric and ds.model(11).symmetric and not ds.model(1).symmetric
    assert ds.model(1).colors is not None


@needs_lmo
def test_register_without_depth_fails_with_one_line(tmp_path, capsys):
    rc = main(["register", "--data", str(LMO), "--method", "ransac", "--out", str(tmp_path / "r.csv"), "--no-progress"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no depth" in err[0]
    assert not (tmp_path / "r.csv").exists()


def test_bop_errors_name_the_file(tmp_path):
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "models_info.json").write_text("{not json")
    with pytest.raises(DatasetError, match="models_info.json"):
        BopDataset(tmp_path, "test")
    (tmp_path / "models" / "models_info.json").write_text(json.dumps({"1": {"diameter": 10.0}}))
    with pytest.raises(DatasetError, match="split 'test' not found"):
        BopDataset(tmp_path, "test")
    sd = tmp_path / "test" / "000001"
    sd.mkdir(parents=True)
    (sd / "scene_gt.json").write_text(json.dumps({"0": [{"obj_id": 1, "cam_R_m2c": [1, 0], "cam_t_m2c": [0, 0, 1]}]}))
    (sd / "scene_camera.json").write_text(json.dumps({"0": {"cam_K": [1, 0, 0, 0, 1, 0, 0, 0, 1], "depth_scale": 1}}))
    ds = BopDataset(tmp_path, "test")
    assert not ds.has_depth
    with pytest.raises(DatasetError, match="rgb"):
        ds[0]


def test_export_bop_round_trip(tmp_path):
    src = write_synthetic_dataset(tmp_path / "syn", n_images=3)
    a = open_dataset(src)
    rc = main(["export-bop", "--data", str(src), "--out", str(tmp_path / "bop")])
    assert rc == 0
    b = open_dataset(tmp_path / "bop", split="test")
    assert isinstance(b, BopDataset) and sorted(b.keys()) == sorted(a.keys())
    info = json.loads((tmp_path / "bop" / "models" / "models_info.json").read_text())
    assert set(info) == {"15"} and info["15"]["diameter"] == pytest.approx(a.model(15).diameter * 1000)
    for i, key in enumerate(a.keys()):
        sa, sb = a[i], b.load(key)
        assert (sa.scene_id, sa.im_id) == (sb.scene_id, sb.im_id)
        np.testing.assert_array_equal(sa.rgb, sb.rgb)
        np.testing.assert_allclose(sb.depth, sa.depth, atol=1e-4)  # 0.1 mm depth unit
        assert ((sb.depth > 0) == (sa.depth > 0)).all()
        np.testing.assert_allclose(sb.K, sa.K)
        assert len(sa.instances) == len(sb.instances)
        for ia, ib in zip(sa.instances, sb.instances, strict=True):
            assert (ia.obj_name, ia.obj_id, ia.inst, ia.px_visib) == (ib.obj_name, ib.obj_id, ib.inst, ib.px_visib)
            np.testing.assert_allclose(ib.R, ia.R, atol=1e-12)
            np.testing.assert_allclose(ib.t, ia.t, atol=1e-9)
            np.testing.assert_array_equal(ib.mask, ia.mask)
    ma, mb = a.model(15), b.model(15)
    np.testing.assert_allclose(mb.points, ma.points, atol=1e-6)
    assert mb.diameter == pytest.approx(ma.diameter) and mb.symmetric == ma.symmetric
    # a second export into the same directory is refused
    assert main(["export-bop", "--data", str(src), "--out", str(tmp_path / "bop")]) == 2
    # a foreign non-empty directory is refused and left as it was (it used to be overwritten)
    foreign = tmp_path / "foreign"
    (foreign / "models").mkdir(parents=True)
    (foreign / "models" / "obj_000001.ply").write_text("mine")
    assert main(["export-bop", "--data", str(src), "--out", str(foreign)]) == 2
    assert (foreign / "models" / "obj_000001.ply").read_text() == "mine"
    assert sorted(p.name for p in foreign.rglob("*")) == ["models", "obj_000001.ply"]


def _exported(tmp_path):
    src = write_synthetic_dataset(tmp_path / "syn", n_images=2, two_instances_in_first=False)
    assert main(["export-bop", "--data", str(src), "--out", str(tmp_path / "bop")]) == 0
    return tmp_path / "bop"


def test_wrong_depth_scale_is_an_error_not_a_wrong_number(tmp_path, capsys):
    """A BOP split whose depth_scale is off by 10x is refused in one line before any registration."""
    bop = _exported(tmp_path)
    for p in (bop / "test").glob("*/scene_camera.json"):
        cams = json.loads(p.read_text())
        p.write_text(json.dumps({k: dict(v, depth_scale=1.0) for k, v in cams.items()}))  # written with 0.1
    capsys.readouterr()
    rc = main(["register", "--data", str(bop), "--method", "ransac", "--out", str(tmp_path / "r.csv"), "--workers", "1",
               "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "depth looks wrongly scaled" in err[0] and not (tmp_path / "r.csv").exists()


def test_malformed_symmetry_annotation_is_a_one_line_error(tmp_path, capsys):
    """BOP scores read the symmetry annotations; a malformed entry names the file and the field."""
    from sixdpose.artifacts.poses import PoseEstimate, write_results

    bop = _exported(tmp_path)
    ds = open_dataset(bop, split="test")
    s = ds[0]
    write_results(
        [PoseEstimate(s.scene_id, s.im_id, g.obj_id, 1.0, g.R, g.t, 0.1) for g in s.instances], tmp_path / "r.csv"
    )
    info_path = bop / "models" / "models_info.json"
    info = json.loads(info_path.read_text())
    info["15"]["symmetries_continuous"] = [{"axis": [0, 0, 0], "offset": [0, 0, 0]}]
    info_path.write_text(json.dumps(info))
    capsys.readouterr()
    rc = main(["evaluate", "--data", str(bop), "--results", str(tmp_path / "r.csv"), "--min-px", "0"])
    err = [line for line in capsys.readouterr().err.splitlines() if "error:" in line]  # (progress bars aside)
    assert rc == 2 and len(err) == 1 and "models_info" in err[0] and "axis" in err[0], err


def test_evaluate_scenes_scores_one_scene_only(tmp_path, capsys):
    """``evaluate --scenes`` scores every image of the named scenes and ignores the other scenes' rows (the
    leave-one-scene-out figures); a scene the dataset lacks is a one-line error."""
    from sixdpose.artifacts.poses import PoseEstimate, write_results

    bop = _exported(tmp_path)
    ds = open_dataset(bop, split="test")
    rows = []
    for s in ds:
        for g in s.instances:  # GT poses in scene 0, a pose 1 m off in the others
            off = 0.0 if s.scene_id == 0 else 1.0
            rows.append(PoseEstimate(s.scene_id, s.im_id, g.obj_id, 1.0, g.R, g.t + off, 0.1))
    write_results(rows, tmp_path / "r.csv")
    keys = ds.keys()
    scenes = sorted({k[0] for k in keys})
    n0 = sum(len(ds.load(k, masks=False, rgb=False, depth=False).instances) for k in keys if k[0] == scenes[0])
    capsys.readouterr()
    assert main(["evaluate", "--data", str(bop), "--results", str(tmp_path / "r.csv"), "--min-px", "0", "--no-bop",
                 "--scenes", str(scenes[0]), "--out", str(tmp_path / "e0"), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert f"ADD(-S) accuracy 100.00% ({n0}/{n0} GT" in out, out
    rc = main(["evaluate", "--data", str(bop), "--results", str(tmp_path / "r.csv"), "--scenes", "99",
               "--out", str(tmp_path / "e1"), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--scenes" in err[0] and "99" in err[0]
