"""Every file read through a schema: a mutated file gives one clear line (or a recorded per-item fault)
naming the file and the key, never a traceback and never a score for data that was not read right;
results are validated before scoring; predicted masks of another dataset are refused."""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from sixdpose.artifacts.poses import PoseEstimate, ResultsError, read_results, write_results
from sixdpose.artifacts.predictions import (
    PredictionError,
    check_predictions_dataset,
    write_predictions,
    write_predictions_meta,
)
from sixdpose.cli import main
from sixdpose.datasets.base import DatasetError
from sixdpose.datasets.bop import BopDataset, export_bop, load_bop_camera
from sixdpose.datasets.readers import dataset_fingerprint, open_dataset
from sixdpose.evaluation.evaluate import evaluate
from test_reg_helpers import YCBV, write_synthetic_dataset


# -- helpers --------------------------------------------------------------------------------------
def run_cli(argv, capsys) -> tuple[int, list[str], str]:
    """Run ``sixdpose ARGV`` in process: ``(exit status, error lines, whole stderr)`` (a parse-time
    refusal, argparse's SystemExit, counts as exit status 2)."""
    capsys.readouterr()
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as e:
        rc = e.code
    err = capsys.readouterr().err
    return rc, [line for line in err.splitlines() if "error:" in line], err


def assert_one_line(rc, lines, err, *needles):
    assert rc == 2, err
    assert "Traceback" not in err and len(lines) == 1, err
    for n in needles:
        assert n in lines[0], (n, lines[0])


@pytest.fixture(scope="module")
def syn(tmp_path_factory) -> Path:
    """A tiny synthetic dataset (3 images, obj_id 15; the first image has two instances)."""
    return write_synthetic_dataset(tmp_path_factory.mktemp("syn") / "syn", n_images=3)


@pytest.fixture(scope="module")
def bop(syn, tmp_path_factory) -> Path:
    """The same dataset exported to BOP (depth_scale 0.1)."""
    out = tmp_path_factory.mktemp("bop") / "bop"
    export_bop(open_dataset(syn), out, progress=False)
    return out


def copy(src: Path, tmp_path: Path, name: str = "d") -> Path:
    dst = tmp_path / name
    shutil.copytree(src, dst)
    return dst


def gt_rows(ds, keys=None, time=0.5) -> list[PoseEstimate]:
    """One perfect row per GT instance."""
    rows = []
    for key in keys or ds.keys():
        s = ds.load(key, rgb=False, depth=False, masks=False)
        rows += [PoseEstimate(s.scene_id, s.im_id, g.obj_id, 1.0, g.R.copy(), g.t.copy(), time) for g in s.instances]
    return rows


def scene_file(bop_root: Path, name: str) -> Path:
    return sorted((bop_root / "test").glob(f"*/{name}"))[0]


def edit_json(path: Path, fn) -> None:
    d = json.loads(path.read_text())
    d = fn(d)
    path.write_text(json.dumps(d))


def first_key(d: dict) -> str:
    return sorted(d, key=int)[0]


# -- BOP calibration: depth_scale and cam_K ---------------------------------------------------------
@pytest.mark.parametrize("value", ["missing", 0, -0.1, "0.1", None])
def test_bop_frame_depth_scale_must_be_given_and_positive(bop, tmp_path, value):
    d = copy(bop, tmp_path)
    cam_path = scene_file(d, "scene_camera.json")

    def mutate(cams):
        k = first_key(cams)
        if value == "missing":
            del cams[k]["depth_scale"]
        else:
            cams[k]["depth_scale"] = value
        return cams

    edit_json(cam_path, mutate)
    im = int(first_key(json.loads(cam_path.read_text())))
    ds = BopDataset(d, "test")
    key = (int(cam_path.parent.name), im)
    with pytest.raises(DatasetError, match=rf"scene_camera.json: image {im}: .*depth_scale") as e:
        ds.load(key)
    assert "\n" not in str(e.value)
    if value in ("missing", None):  # null: no depth unit either
        ds.load(key, depth=False)  # annotations and RGB are still readable without the depth unit
    else:
        with pytest.raises(DatasetError, match="depth_scale"):
            ds.load(key, depth=False)  # a malformed entry is refused whatever is read


@pytest.mark.parametrize("K", [[0] * 9, [-500, 0, 80, 0, 500, 60, 0, 0, 1], [float("nan"), 0, 80, 0, 500, 60, 0, 0, 1],
                               [500, 0, 80, 0, 500, 60], "500"])
def test_bop_frame_degenerate_cam_K_is_refused(bop, tmp_path, K):
    d = copy(bop, tmp_path)
    cam_path = scene_file(d, "scene_camera.json")
    edit_json(cam_path, lambda cams: {k: dict(v, cam_K=K) for k, v in cams.items()})
    ds = BopDataset(d, "test")
    keys = ds.keys()
    key = next(k for k in keys if k[0] == int(cam_path.parent.name))
    with pytest.raises(DatasetError, match=rf"scene_camera.json: image {key[1]}: cam_K"):
        ds.load(key, rgb=False, depth=False)


def test_register_records_a_frame_without_depth_scale_and_scores_nothing_for_it(bop, tmp_path, capsys):
    """The frame is a recorded per-item fault naming file, frame and field; no pose row for it."""
    d = copy(bop, tmp_path)
    cam_path = scene_file(d, "scene_camera.json")
    sid = int(cam_path.parent.name)
    edit_json(cam_path, lambda cams: {k: {"cam_K": v["cam_K"]} for k, v in cams.items()})  # no depth_scale at all
    out = tmp_path / "r.csv"
    rc, lines, err = run_cli(["register", "--data", d, "--method", "ransac", "--out", out, "--workers", 1,
                              "--no-progress"], capsys)
    assert rc == 0 and not lines, err
    rows = read_results(out)
    assert rows and all(r.scene_id != sid for r in rows)  # the other scene was registered
    skipped = (tmp_path / "r_skipped_images.csv").read_text()
    assert "scene_camera.json" in skipped and "depth_scale" in skipped and f"{sid}," in skipped


@pytest.mark.skipif(not YCBV.is_dir(), reason="shared/data/ycbv_sample not available")
@pytest.mark.parametrize("value", ["missing", 0, -1.0])
def test_ycbv_without_a_valid_depth_scale_is_not_read_ten_times_too_far(tmp_path, value):
    """YCB-Video depth is in 0.1 mm: no default of 1.0 may be invented for a frame that lacks its unit."""
    d = tmp_path / "ycbv"
    (d / "models").mkdir(parents=True)
    shutil.copy(YCBV / "models" / "models_info.json", d / "models")
    sd = d / "train_real" / "000000"
    src = YCBV / "train_real" / "000000"
    for sub in ("rgb", "depth", "mask_visib"):
        (sd / sub).mkdir(parents=True)
        for p in sorted((src / sub).glob("000001*")):
            shutil.copy(p, sd / sub)
    for name in ("scene_gt.json", "scene_camera.json", "scene_gt_info.json"):
        full = json.loads((src / name).read_text())
        (sd / name).write_text(json.dumps({"1": full["1"]}))
    ds = BopDataset(d, "train_real")
    assert 0.3 < np.median(ds.load((0, 1)).depth[ds.load((0, 1)).depth > 0]) < 2.0
    cams = json.loads((sd / "scene_camera.json").read_text())
    if value == "missing":
        del cams["1"]["depth_scale"]
    else:
        cams["1"]["depth_scale"] = value
    (sd / "scene_camera.json").write_text(json.dumps(cams))
    with pytest.raises(DatasetError, match=r"scene_camera.json: image 1: .*depth_scale"):
        BopDataset(d, "train_real").load((0, 1))


# -- export-bop ------------------------------------------------------------------------------------
@pytest.mark.parametrize("scale", ["0", "-0.1", "nan", "inf"])
def test_export_bop_refuses_a_non_positive_depth_scale(syn, tmp_path, capsys, scale):
    out = tmp_path / "out"
    rc, lines, err = run_cli(["export-bop", "--data", syn, "--out", out, f"--depth-scale={scale}"], capsys)
    assert_one_line(rc, lines, err, "depth-scale")
    assert not out.exists()


@pytest.mark.parametrize("split", ["../x", "a/b", "/tmp/abs_split", "..", ""])
def test_export_bop_refuses_a_split_that_is_a_path(syn, tmp_path, capsys, split):
    out = tmp_path / "out"
    rc, lines, err = run_cli(["export-bop", "--data", syn, "--out", out, f"--split={split}"], capsys)
    assert_one_line(rc, lines, err, "split")
    assert not out.exists() and not (tmp_path / "x").exists() and not Path("/tmp/abs_split").exists()


def test_reading_a_split_that_is_a_path_is_refused(bop):
    with pytest.raises(DatasetError, match="split"):
        BopDataset(bop, "../bop")


# -- evaluate: results validated before scoring ----------------------------------------------------
def _evaluate_rows(ds, rows):
    return evaluate(ds, rows, min_px=0, images=ds.keys())


def test_perfect_rows_score_100(syn):
    ds = open_dataset(syn)
    res = _evaluate_rows(ds, gt_rows(ds))
    assert res.accuracy == 100.0 and res.n_rejected == 0 and res.n_duplicates == 0


@pytest.mark.parametrize("kind", ["scaled", "singular", "reflection", "zeros", "nan_R", "nan_t", "unknown_obj"])
def test_rows_that_are_not_poses_are_never_credited(syn, kind):
    ds = open_dataset(syn)
    rows = gt_rows(ds)
    bad = rows[0]
    if kind == "scaled":
        bad.R = 2.0 * bad.R
    elif kind == "singular":
        bad.R = bad.R @ np.diag([1.0, 1.0, 0.0])  # rank 2, det 0: flattens the object onto a plane
    elif kind == "reflection":
        bad.R = bad.R @ np.diag([1.0, 1.0, -1.0])  # orthonormal, det -1
    elif kind == "zeros":
        bad.R = np.zeros((3, 3))
    elif kind == "nan_R":
        bad.R = bad.R.copy()
        bad.R[0, 0] = np.nan
    elif kind == "nan_t":
        bad.t = np.array([np.nan, 0.0, 0.5])
    elif kind == "unknown_obj":
        bad.obj_id = 99
    res = _evaluate_rows(ds, rows)
    assert res.n_rejected == 1 and res.rejected[0][:2] == (bad.scene_id, bad.im_id)
    rec = [r for r in res.records if (r.scene_id, r.im_id) == (bad.scene_id, bad.im_id)]
    assert res.n_correct == res.n_gt - 1  # the instance of the bad row is not credited
    assert sum(not r.correct for r in rec) == 1 and all(r.estimate is not bad for r in rec)


def test_a_rotation_within_tolerance_is_accepted(syn):
    ds = open_dataset(syn)
    rows = gt_rows(ds)
    rows[0].R = rows[0].R + 1e-5  # rounding of a written CSV
    assert _evaluate_rows(ds, rows).n_rejected == 0


def test_duplicate_rows_are_counted_once(syn, caplog):
    ds = open_dataset(syn)
    once = _evaluate_rows(ds, gt_rows(ds))
    with caplog.at_level(logging.WARNING, logger="sixdpose"):
        twice = _evaluate_rows(ds, gt_rows(ds) + gt_rows(ds))
    assert twice.n_duplicates == len(gt_rows(ds))
    assert twice.accuracy == once.accuracy and twice.n_estimates == once.n_estimates
    assert twice.instances_per_s == pytest.approx(once.instances_per_s) and twice.fps == pytest.approx(once.fps)
    assert "counted once" in caplog.text and "repeat" in caplog.text


def test_a_pose_repeated_with_another_score_is_counted_once(syn):
    ds = open_dataset(syn)
    rows = gt_rows(ds)
    again = [PoseEstimate(r.scene_id, r.im_id, r.obj_id, 0.5, r.R, r.t, r.time) for r in rows]
    res = _evaluate_rows(ds, rows + again)
    assert res.n_duplicates == len(rows) and res.n_estimates == len(rows) and res.accuracy == 100.0


def test_timing_counts_each_image_once(syn):
    ds = open_dataset(syn)
    res = _evaluate_rows(ds, gt_rows(ds, time=0.5))
    assert res.total_time == pytest.approx(0.5 * len(ds)) and res.fps == pytest.approx(2.0)


def _strict_json(path: Path):
    def no_constant(c):
        raise AssertionError(f"{path}: not valid JSON ({c})")

    return json.loads(path.read_text(), parse_constant=no_constant)


@pytest.mark.parametrize("bad", ["negative_time", "nan_time", "nan_R", "R_of_8", "text_id"])
def test_evaluate_refuses_a_malformed_results_csv(syn, tmp_path, capsys, bad):
    ds = open_dataset(syn)
    csv = tmp_path / "r.csv"
    write_results(gt_rows(ds), csv)
    lines = csv.read_text().splitlines()
    f = lines[1].split(",")
    if bad == "negative_time":
        f[6] = "-0.1"
    elif bad == "nan_time":
        f[6] = "nan"
    elif bad == "nan_R":
        f[4] = "nan " + " ".join(f[4].split()[1:])
    elif bad == "R_of_8":
        f[4] = " ".join(f[4].split()[:8])
    elif bad == "text_id":
        f[2] = "power_drill"
    lines[1] = ",".join(f)
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(ResultsError, match="r.csv: line 2"):
        read_results(csv)
    rc, lines_, err = run_cli(["evaluate", "--data", syn, "--results", csv, "--no-progress", "--no-bop"], capsys)
    assert_one_line(rc, lines_, err, "r.csv", "line 2")
    assert not (tmp_path / "r_eval").exists()


def test_summary_json_is_always_valid_json(syn, tmp_path, capsys):
    """No GT counted, zero times: accuracy and fps are undefined and written as null, not NaN."""
    ds = open_dataset(syn)
    csv = tmp_path / "r.csv"
    write_results(gt_rows(ds, time=0.0), csv)
    rc, lines, err = run_cli(["evaluate", "--data", syn, "--results", csv, "--no-progress", "--min-px", "1000000"],
                             capsys)
    assert rc == 0, err
    summary = _strict_json(tmp_path / "r_eval" / "summary.json")
    assert summary["fps"] is None and summary["accuracy"] is None and summary["n_rejected"] == 0


def test_evaluate_cli_reports_rejected_and_duplicate_rows(syn, tmp_path, capsys):
    ds = open_dataset(syn)
    rows = gt_rows(ds)
    rows[0].R = rows[0].R @ np.diag([1.0, 1.0, -1.0])
    csv = tmp_path / "r.csv"
    write_results(rows + rows[1:2], csv)
    rc, lines, err = run_cli(["evaluate", "--data", syn, "--results", csv, "--no-progress", "--min-px", "0"], capsys)
    assert rc == 0, err
    summary = _strict_json(tmp_path / "r_eval" / "summary.json")
    assert summary["n_rejected"] == 1 and summary["n_duplicates"] == 1
    assert summary["n_correct"] == summary["n_gt"] - 1


def test_rejected_rows_do_not_take_their_image_out_of_the_evaluation(syn, tmp_path, capsys):
    """By default only images with rows are evaluated: an image whose every row is rejected is still one."""
    ds = open_dataset(syn)
    rows = gt_rows(ds)
    first = (rows[0].scene_id, rows[0].im_id)
    for r in rows:
        if (r.scene_id, r.im_id) == first:
            r.R = r.R @ np.diag([1.0, 1.0, -1.0])
    n_bad = sum((r.scene_id, r.im_id) == first for r in rows)
    res = evaluate(ds, rows, min_px=0)
    assert res.n_rejected == n_bad and res.n_gt == len(rows) and res.n_correct == len(rows) - n_bad
    assert res.n_images == len(ds)  # the image's time is still counted once
    csv = tmp_path / "r.csv"
    write_results(rows, csv)
    capsys.readouterr()
    assert main(["evaluate", "--data", str(syn), "--results", str(csv), "--no-progress", "--min-px", "0"]) == 0
    assert f"{n_bad} rejected row(s)" in capsys.readouterr().out
    summary = _strict_json(tmp_path / "r_eval" / "summary.json")
    assert summary["n_gt"] == len(rows) and summary["n_correct"] == len(rows) - n_bad


# -- every file of a BOP set mutated ---------------------------------------------------------------
def _remove_key(d, key):
    """Delete ``key`` from the first image's first entry (or the first object's entry)."""
    k = first_key(d)
    entry = d[k][0] if isinstance(d[k], list) else d[k]
    del entry[key]
    return d


def _swap_type(d, key, value):
    k = first_key(d)
    entry = d[k][0] if isinstance(d[k], list) else d[k]
    entry[key] = value
    return d


BOP_MUTATIONS = {
    # file: [(mutation name, function on the loaded JSON or "truncate", words the error line must contain)]
    "models_info.json": [
        ("no diameter", lambda d: _remove_key(d, "diameter"), ["models_info.json", "diameter"]),
        ("diameter 0", lambda d: _swap_type(d, "diameter", 0), ["models_info.json", "diameter"]),
        ("diameter string", lambda d: _swap_type(d, "diameter", "100"), ["models_info.json", "diameter"]),
        ("list for dict", lambda d: list(d.values()), ["models_info.json"]),
        ("object key not integer", lambda d: {"obj_a" if k == first_key(d) else k: v for k, v in d.items()},
         ["models_info.json", "obj_a"]),
        ("truncated", "truncate", ["models_info.json", "corrupt JSON"]),
    ],
    "scene_gt.json": [
        ("no obj_id", lambda d: _remove_key(d, "obj_id"), ["scene_gt.json", "obj_id"]),
        ("no cam_R_m2c", lambda d: _remove_key(d, "cam_R_m2c"), ["scene_gt.json", "cam_R_m2c"]),
        ("obj_id string", lambda d: _swap_type(d, "obj_id", "15"), ["scene_gt.json", "obj_id"]),
        ("t of 2", lambda d: _swap_type(d, "cam_t_m2c", [0, 0]), ["scene_gt.json", "cam_t_m2c"]),
        ("dict for list", lambda d: {k: (v[0] if k == first_key(d) else v) for k, v in d.items()}, ["scene_gt.json"]),
        ("image key not integer", lambda d: {"x" + k: v for k, v in d.items()}, ["scene_gt.json", "image key"]),
        ("truncated", "truncate", ["scene_gt.json", "corrupt JSON"]),
    ],
    "scene_camera.json": [
        ("no cam_K", lambda d: _remove_key(d, "cam_K"), ["scene_camera.json", "cam_K"]),
        ("cam_K strings", lambda d: _swap_type(d, "cam_K", [str(v) for v in d[first_key(d)]["cam_K"]]),
         ["scene_camera.json", "cam_K"]),
        ("list for dict", lambda d: {k: [v] for k, v in d.items()}, ["scene_camera.json"]),
        ("truncated", "truncate", ["scene_camera.json", "corrupt JSON"]),
    ],
    "scene_gt_info.json": [
        ("px_count_visib string", lambda d: _swap_type(d, "px_count_visib", "many"),
         ["scene_gt_info.json", "px_count_visib"]),
        ("px_count_visib negative", lambda d: _swap_type(d, "px_count_visib", -5),
         ["scene_gt_info.json", "px_count_visib"]),
        ("truncated", "truncate", ["scene_gt_info.json", "corrupt JSON"]),
    ],
}
BOP_CASES = [(f, name, fn, words) for f, cases in BOP_MUTATIONS.items() for name, fn, words in cases]


def _mutate_file(path: Path, fn) -> None:
    if fn == "truncate":
        text = path.read_text()
        path.write_text(text[: len(text) // 2])
    else:
        edit_json(path, fn)


@pytest.mark.parametrize("fname,name,fn,words", BOP_CASES, ids=[f"{c[0]}-{c[1]}" for c in BOP_CASES])
def test_mutated_bop_json_gives_one_line(bop, tmp_path, capsys, fname, name, fn, words):
    d = copy(bop, tmp_path)
    path = d / "models" / fname if fname == "models_info.json" else scene_file(d, fname)
    ds = open_dataset(bop, split="test")
    csv = tmp_path / "r.csv"
    write_results(gt_rows(ds), csv)
    _mutate_file(path, fn)
    rc, lines, err = run_cli(["evaluate", "--data", d, "--results", csv, "--no-progress", "--min-px", "0"], capsys)
    assert_one_line(rc, lines, err, *words)
    assert not (tmp_path / "r_eval").exists()  # no score for data that was not read right


@pytest.mark.parametrize("mutation", ["no fx", "fx string", "fx zero", "cam_K of 4", "truncated", "list"])
def test_mutated_camera_json_gives_one_line(tmp_path, mutation):
    cam = {"fx": 500.0, "fy": 501.0, "cx": 159.5, "cy": 119.5, "width": 320, "height": 240, "depth_scale": 0.1}
    path = tmp_path / "camera.json"
    if mutation == "no fx":
        del cam["fx"]
    elif mutation == "fx string":
        cam["fx"] = "500"
    elif mutation == "fx zero":
        cam["fx"] = 0
    elif mutation == "cam_K of 4":
        cam = {"cam_K": [500, 0, 159.5, 0]}
    path.write_text(json.dumps(cam))
    if mutation == "truncated":
        path.write_text(json.dumps(cam)[:20])
    elif mutation == "list":
        path.write_text(json.dumps([cam]))
    with pytest.raises(DatasetError, match="camera.json") as e:
        load_bop_camera(path)
    assert "\n" not in str(e.value)


# -- images of the wrong mode or bit depth ------------------------------------------------------------
def _key_of_scene_dir(d: Path) -> tuple[int, int]:
    im = int(sorted(json.loads((d / "scene_gt.json").read_text()), key=int)[0])
    return int(d.name), im


@pytest.mark.parametrize("what", ["depth 8-bit", "depth RGB", "rgb 16-bit", "mask 16-bit", "rgb not an image"])
def test_bop_images_are_checked_for_mode_and_bit_depth(bop, tmp_path, capsys, what):
    d = copy(bop, tmp_path)
    sd = scene_file(d, "scene_gt.json").parent
    key = _key_of_scene_dir(sd)
    name = f"{key[1]:06d}"
    dpath, rpath = sd / "depth" / f"{name}.png", sd / "rgb" / f"{name}.png"
    mpath = sd / "mask_visib" / f"{name}_000000.png"
    raw = np.asarray(Image.open(dpath))
    if what == "depth 8-bit":  # millimetres squeezed into 8 bits: would be read at the wrong scale
        Image.fromarray(np.clip(raw // 10, 0, 255).astype(np.uint8)).save(dpath)
        target, words = dpath, ["16-bit"]
    elif what == "depth RGB":
        Image.fromarray(np.zeros(raw.shape + (3,), np.uint8)).save(dpath)
        target, words = dpath, ["16-bit"]
    elif what == "rgb 16-bit":
        Image.fromarray(raw).save(rpath)
        target, words = rpath, ["8-bit RGB"]
    elif what == "mask 16-bit":
        Image.fromarray(raw).save(mpath)
        target, words = mpath, ["mask"]
    else:
        rpath.write_bytes(b"not an image")
        target, words = rpath, ["unreadable"]
    ds = BopDataset(d, "test")
    with pytest.raises(DatasetError, match=str(target.name)) as e:
        ds.load(key)
    assert all(w in str(e.value) for w in words), str(e.value)
    # register records the frame as skipped (naming the file), registers the rest, scores nothing for it
    out = tmp_path / "r.csv"
    rc, lines, err = run_cli(["register", "--data", d, "--method", "ransac", "--out", out, "--workers", 1,
                              "--no-progress"], capsys)
    assert rc == 0 and not lines, err
    assert all((r.scene_id, r.im_id) != key for r in read_results(out))
    assert target.name in (tmp_path / "r_skipped_images.csv").read_text()


# -- every file of a synthetic set mutated ---------------------------------------------------------
def _without(d: dict, key: str) -> dict:
    return {k: v for k, v in d.items() if k != key}


SYN_MUTATIONS = {
    "gt.yml": [
        ("no scene_id", lambda g: {k: _without(v, "scene_id") if k == 0 else v for k, v in g.items()},
         ["gt.yml", "scene_id"]),
        ("no cam_K", lambda g: {k: _without(v, "cam_K") if k == 0 else v for k, v in g.items()},
         ["gt.yml", "image 0", "cam_K"]),
        ("cam_K zeros", lambda g: {k: dict(v, cam_K=[[0, 0, 0]] * 3) for k, v in g.items()},
         ["gt.yml", "cam_K", "focal"]),
        ("R string", lambda g: {k: dict(v, objects=[dict(o, R="eye") for o in v["objects"]]) for k, v in g.items()},
         ["gt.yml", "objects[0].R"]),
        ("obj_name path",
         lambda g: {k: dict(v, objects=[dict(o, obj_name="../x") for o in v["objects"]]) for k, v in g.items()},
         ["gt.yml", "obj_name"]),
        ("list for mapping", lambda g: list(g.values()), ["gt.yml"]),
        ("truncated", "truncate", ["gt.yml", "corrupt YAML"]),
    ],
    "models/models_info.yml": [
        ("diameter 0", lambda m: {k: dict(v, diameter=0.0) for k, v in m.items()}, ["models_info.yml", "diameter"]),
        ("no obj_id", lambda m: {k: _without(v, "obj_id") for k, v in m.items()}, ["models_info.yml", "obj_id"]),
        ("diameter string", lambda m: {k: dict(v, diameter="0.1") for k, v in m.items()},
         ["models_info.yml", "diameter"]),
        ("truncated", "truncate", ["models_info.yml"]),
    ],
    "manifest.json": [
        ("truncated", "truncate", ["manifest.json", "corrupt JSON"]),
        ("list", lambda m: [m], ["manifest.json"]),
    ],
}
SYN_CASES = [(f, name, fn, words) for f, cases in SYN_MUTATIONS.items() for name, fn, words in cases]


@pytest.mark.parametrize("fname,name,fn,words", SYN_CASES, ids=[f"{c[0]}-{c[1]}" for c in SYN_CASES])
def test_mutated_synthetic_file_gives_one_line(syn, tmp_path, capsys, fname, name, fn, words):
    import yaml

    d = copy(syn, tmp_path)
    ds = open_dataset(syn)
    csv = tmp_path / "r.csv"
    write_results(gt_rows(ds), csv)
    path = d / fname
    if fn == "truncate":
        text = path.read_text()
        cut = text[: len(text) // 2]
        path.write_text(cut + ("\n  - [unclosed" if path.suffix == ".yml" else ""))
    elif path.suffix == ".yml":
        path.write_text(yaml.safe_dump(fn(yaml.safe_load(path.read_text()))))
    else:
        edit_json(path, fn)
    rc, lines, err = run_cli(["evaluate", "--data", d, "--results", csv, "--no-progress", "--min-px", "0"], capsys)
    assert_one_line(rc, lines, err, *words)
    assert not (tmp_path / "r_eval").exists()


@pytest.mark.parametrize("what", ["depth int", "depth 3-D", "rgb grey", "rgb 16-bit", "mask rgb"])
def test_synthetic_images_are_checked(syn, tmp_path, what):
    d = copy(syn, tmp_path)
    ds = open_dataset(d)
    key = ds.keys()[1]
    im = key[1]
    s = ds.load(key)
    if what == "depth int":  # millimetres as integers: would be read 1000x too far
        target = d / "depth" / f"{im}.npy"
        np.save(target, (s.depth * 1000).astype(np.uint16))
    elif what == "depth 3-D":
        target = d / "depth" / f"{im}.npy"
        np.save(target, np.repeat(s.depth[..., None], 3, axis=2))
    elif what == "rgb grey":
        target = d / "RGB" / f"{im}.png"
        Image.fromarray(s.rgb[..., 0]).save(target)
    elif what == "rgb 16-bit":
        target = d / "RGB" / f"{im}.png"
        Image.fromarray(s.rgb[..., 0].astype(np.uint16) * 256).save(target)
    else:
        inst = s.instances[0]
        target = d / "masks" / inst.obj_name / f"{im}_{inst.inst}.png"
        Image.fromarray(np.repeat((inst.mask * 255).astype(np.uint8)[..., None], 3, axis=2)).save(target)
    with pytest.raises(DatasetError, match=str(target.name)) as e:
        open_dataset(d).load(key)
    assert "\n" not in str(e.value)


# -- segment output (predicted masks) ----------------------------------------------------------------
def _segment_output(ds, pred: Path, fingerprint: str | None = "auto") -> Path:
    """What ``sixdpose segment`` writes for ``ds`` with perfect masks: npz files, coco_results.json, meta.json."""
    from sixdpose.segmentation.data import ClassMap
    from sixdpose.segmentation.evaluate import coco_ground_truth

    classes = ClassMap.from_dataset(ds)
    samples = [ds[i] for i in range(len(ds))]
    for s in samples:
        write_predictions(pred, s.scene_id, s.im_id, np.stack([g.mask for g in s.instances]),
                          [g.obj_id for g in s.instances], np.full(len(s.instances), 0.9, np.float32))
    gt, _ = coco_ground_truth(samples, classes)
    results = [{"image_id": a["image_id"], "category_id": a["category_id"], "segmentation": a["segmentation"],
                "bbox": a["bbox"], "score": 0.9} for a in gt["annotations"]]
    (pred / "coco_results.json").write_text(json.dumps(results))
    meta = {"checkpoint": "/nowhere/ckpt", "epoch": 1, "classes": classes.to_list(), "score_thresh": 0.05,
            "data": str(ds.location), "split": "test", "subset": "all",
            "images": [[s.scene_id, s.im_id, *s.rgb.shape[:2]] for s in samples]}
    if fingerprint == "auto":
        meta["dataset_fingerprint"] = dataset_fingerprint(ds)
    elif fingerprint is not None:
        meta["dataset_fingerprint"] = fingerprint
    write_predictions_meta(pred, meta)
    return pred


@pytest.fixture(scope="module")
def seg_out(syn, tmp_path_factory):
    return _segment_output(open_dataset(syn), tmp_path_factory.mktemp("pred") / "pred")


def test_segment_output_evaluates(syn, seg_out):
    from sixdpose.segmentation.evaluate import evaluate as eval_seg

    assert eval_seg(syn, seg_out)["overall"]["mask"]["AP"] == pytest.approx(1.0)


PRED_MUTATIONS = [
    ("meta.json", "truncated", "truncate", ["meta.json", "corrupt JSON"]),
    ("meta.json", "no classes", lambda m: {k: v for k, v in m.items() if k != "classes"}, ["meta.json", "classes"]),
    ("meta.json", "no images", lambda m: {k: v for k, v in m.items() if k != "images"}, ["meta.json", "images"]),
    ("meta.json", "images strings", lambda m: dict(m, images=[["0", "1"]]), ["meta.json", "images"]),
    ("meta.json", "score_thresh negative", lambda m: dict(m, score_thresh=-0.5), ["meta.json", "score_thresh"]),
    ("meta.json", "list", lambda m: [m], ["meta.json"]),
    ("coco_results.json", "truncated", "truncate", ["coco_results.json", "corrupt JSON"]),
    ("coco_results.json", "no segmentation", lambda r: [{k: v for k, v in e.items() if k != "segmentation"} for e in r],
     ["coco_results.json", "entry 0", "segmentation"]),
    ("coco_results.json", "score string", lambda r: [dict(e, score="high") for e in r], ["coco_results.json", "score"]),
    ("coco_results.json", "bbox of 3", lambda r: [dict(e, bbox=e["bbox"][:3]) for e in r],
     ["coco_results.json", "bbox"]),
    ("coco_results.json", "dict for list", lambda r: {"results": r}, ["coco_results.json"]),
]


@pytest.mark.parametrize("fname,name,fn,words", PRED_MUTATIONS, ids=[f"{c[0]}-{c[1]}" for c in PRED_MUTATIONS])
def test_mutated_segment_output_gives_one_line(syn, seg_out, tmp_path, capsys, fname, name, fn, words):
    from sixdpose.segmentation.evaluate import evaluate as eval_seg

    pred = copy(seg_out, tmp_path, "pred")
    _mutate_file(pred / fname, fn)
    with pytest.raises(PredictionError) as e:
        eval_seg(syn, pred)
    assert all(w in str(e.value) for w in words) and "\n" not in str(e.value), str(e.value)
    if fname == "meta.json" and name not in ("no classes", "no images"):  # register checks meta.json first
        rc, lines, err = run_cli(["register", "--data", syn, "--method", "ransac", "--masks", pred,
                                  "--out", tmp_path / "r.csv", "--workers", 1, "--no-progress"], capsys)
        assert_one_line(rc, lines, err, "meta.json")
        assert not (tmp_path / "r.csv").exists()


@pytest.mark.parametrize("bad", ["score 1.5", "score negative", "labels float"])
def test_prediction_file_out_of_range_is_refused(tmp_path, bad):
    from sixdpose.artifacts.predictions import read_predictions

    masks = np.zeros((1, 4, 5), bool)
    labels, scores = np.array([15], np.int32), np.array([0.9], np.float32)
    if bad == "score 1.5":
        scores[0] = 1.5
    elif bad == "score negative":
        scores[0] = -0.1
    else:
        labels = np.array([15.5])
    np.savez(tmp_path / "0_1.npz", masks=masks, labels=labels, scores=scores)
    with pytest.raises(PredictionError, match=r"0_1.npz: (scores|labels)"):
        read_predictions(tmp_path, 0, 1)


# -- predictions of another dataset -------------------------------------------------------------------
@pytest.fixture(scope="module")
def other(tmp_path_factory) -> Path:
    """Another synthetic dataset with the same object and image keys (seed 1)."""
    return write_synthetic_dataset(tmp_path_factory.mktemp("other") / "other", n_images=3, seed=1)


def test_fingerprint_tells_datasets_and_splits_apart(syn, other, bop):
    a, b = dataset_fingerprint(open_dataset(syn)), dataset_fingerprint(open_dataset(other))
    assert a and b and a != b
    assert dataset_fingerprint(open_dataset(syn)) == a  # stable
    assert dataset_fingerprint(open_dataset(bop, split="test")) not in (a, b)
    # a BOP reader restricted to some scenes still has the split's fingerprint
    assert dataset_fingerprint(BopDataset(bop, "test", scene_ids=[0])) == dataset_fingerprint(BopDataset(bop, "test"))


def test_foreign_predictions_are_refused(syn, other, seg_out, tmp_path, capsys):
    from sixdpose.segmentation.evaluate import evaluate as eval_seg

    assert open_dataset(other).keys() == open_dataset(syn).keys()  # same image keys: only the fingerprint tells
    with pytest.raises(PredictionError, match="another dataset") as e:
        check_predictions_dataset(seg_out, open_dataset(other))
    assert str(syn) in str(e.value) and str(other) in str(e.value)
    check_predictions_dataset(seg_out, open_dataset(syn))
    with pytest.raises(PredictionError, match="another dataset"):
        eval_seg(other, seg_out)
    out = tmp_path / "r.csv"
    rc, lines, err = run_cli(["register", "--data", other, "--method", "ransac", "--masks", seg_out, "--out", out,
                              "--workers", 1, "--no-progress"], capsys)
    assert_one_line(rc, lines, err, "another dataset", str(syn), str(other))
    assert not out.exists()
    rc, lines, err = run_cli(["register", "--data", syn, "--method", "ransac", "--masks", seg_out, "--out", out,
                              "--workers", 1, "--no-progress", "--limit", 1], capsys)
    assert rc == 0 and out.exists(), err


def test_foreign_predictions_refused_by_pose_stages(other, seg_out, tmp_path, monkeypatch):
    """predict-pose and train-pose check the prediction directory before using it."""
    pytest.importorskip("torch")
    from sixdpose.pose import infer

    class NoEstimator:
        def predict(self, sample, dets):  # pragma: no cover - must not be reached
            raise AssertionError("masks of another dataset were used")

    with pytest.raises(PredictionError, match="another dataset"):
        infer.predict_dataset(other, None, masks=str(seg_out), estimator=NoEstimator())
    from sixdpose.pose.train import train_pose

    with pytest.raises(PredictionError, match="another dataset"):
        train_pose(other, tmp_path / "run", masks=str(seg_out), profile="smoke")
    assert not (tmp_path / "run").exists()


def test_predictions_without_fingerprint_are_accepted_with_a_warning(syn, tmp_path, caplog):
    pred = _segment_output(open_dataset(syn), tmp_path / "old", fingerprint=None)
    with caplog.at_level(logging.WARNING, logger="sixdpose"):
        check_predictions_dataset(pred, open_dataset(syn))
    assert "no dataset fingerprint" in caplog.text
    bad = _segment_output(open_dataset(syn), tmp_path / "badfp", fingerprint="not-a-digest")
    with pytest.raises(PredictionError, match="dataset_fingerprint"):
        check_predictions_dataset(bad, open_dataset(syn))


@pytest.mark.parametrize("info, key", [({"1": {"diameter": "big"}}, "diameter"), ({"1": {"diameter": 0}}, "diameter"),
                                       ({"x": {"diameter": 10.0}}, "x"), ([1, 2], "models_info")])
def test_bop_models_of_the_assets_stage_read_through_the_schema(tmp_path, info, key):
    """``generate --bop-models`` lists a BOP models directory: its models_info.json is checked like the
    dataset reader's (one line naming the file and the key)."""
    from sixdpose.assets.bop import list_bop_models
    from sixdpose.assets.ycb import AssetError

    d = tmp_path / "models"
    d.mkdir()
    (d / "obj_000001.ply").write_text("ply\n")
    (d / "models_info.json").write_text(json.dumps(info))
    with pytest.raises(AssetError, match="models_info.json") as e:
        list_bop_models(d)
    assert key in str(e.value) and "\n" not in str(e.value)
