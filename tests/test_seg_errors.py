"""Bad input to inference and evaluation: corrupt / incompatible checkpoints, images without
annotations, classes missing from the evaluated images, BOP data."""

from __future__ import annotations

import json
import logging
import math
import os
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("pycocotools")

from sixdpose.runs import save_checkpoint  # noqa: E402
from sixdpose.segmentation import checkpoint as ck  # noqa: E402
from sixdpose.segmentation.config import profile_config  # noqa: E402
from sixdpose.segmentation.data import ClassMap  # noqa: E402

SHARED = Path(os.environ.get("SIXDPOSE_SHARED", Path(__file__).resolve().parents[1] / ".." / "shared"))


def make_run(run: Path, classes: ClassMap, **cfg_changes) -> Path:
    """A run directory holding an untrained (random) model.pt for ``classes``."""
    from sixdpose.segmentation.model import build_model

    cfg = profile_config("smoke", **cfg_changes)
    torch.manual_seed(0)
    model, init = build_model(cfg, len(classes))
    run.mkdir(parents=True, exist_ok=True)
    cfg.save(run / "config.json")
    save_checkpoint(
        ck.weights(cfg, classes.to_list(), init, model.state_dict()),
        run / ck.FINAL,
    )
    return run


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    from sixdpose.segmentation.toydata import make_toy_dataset

    return make_toy_dataset(tmp_path_factory.mktemp("toy") / "toy", n_scenes=1, views=3, seed=2)


@pytest.fixture(scope="module")
def run(toy, tmp_path_factory):
    from sixdpose.datasets import open_dataset

    return make_run(tmp_path_factory.mktemp("run") / "run", ClassMap.from_dataset(open_dataset(toy)))


# -- checkpoints --------------------------------------------------------------------------------
def test_missing_checkpoint(tmp_path):
    from sixdpose.segmentation import Segmenter

    with pytest.raises(ck.CheckpointError, match="not found"):
        Segmenter(tmp_path / "nope.pt")
    (tmp_path / "empty_run").mkdir()
    with pytest.raises(ck.CheckpointError, match="no model.pt or last.pt"):
        Segmenter(tmp_path / "empty_run")


@pytest.mark.parametrize("kind", ["garbage", "truncated", "foreign", "version", "incomplete"])
def test_corrupt_or_foreign_checkpoint(run, tmp_path, kind):
    from sixdpose.segmentation import Segmenter

    p = tmp_path / "model.pt"
    good = (run / ck.FINAL).read_bytes()
    if kind == "garbage":
        p.write_bytes(b"this is not a checkpoint" * 10)
        match = "corrupt or unreadable"
    elif kind == "truncated":
        p.write_bytes(good[: len(good) // 2])
        match = "corrupt or unreadable"
    elif kind == "foreign":
        torch.save({"state_dict": {}}, p)
        match = "not a sixdpose segmentation checkpoint"
    elif kind == "version":
        c = torch.load(run / ck.FINAL, weights_only=True)
        torch.save({**c, "version": 99}, p)
        match = "version 99 is not supported"
    else:
        c = torch.load(run / ck.FINAL, weights_only=True)
        del c["classes"]
        torch.save(c, p)
        match = "incomplete checkpoint"
    with pytest.raises(ck.CheckpointError, match=match):
        Segmenter(p)


def test_checkpoint_not_matching_its_config(run, tmp_path):
    """Weights of another architecture (config edited, classes changed) are refused, not half-loaded."""
    from sixdpose.segmentation import Segmenter

    c = torch.load(run / ck.FINAL, weights_only=True)
    cfg = dict(c["config"], fpn_channels=32)
    torch.save({**c, "config": cfg}, tmp_path / "a.pt")
    with pytest.raises(ck.CheckpointError, match="incompatible checkpoint"):
        Segmenter(tmp_path / "a.pt")
    torch.save({**c, "classes": c["classes"][:2]}, tmp_path / "b.pt")
    with pytest.raises(ck.CheckpointError, match="incompatible checkpoint"):
        Segmenter(tmp_path / "b.pt")
    torch.save({**c, "config": dict(c["config"], bogus=1)}, tmp_path / "c.pt")
    with pytest.raises(ck.CheckpointError, match="unknown config field"):
        Segmenter(tmp_path / "c.pt")


def test_checkpoint_of_other_objects_is_refused(toy, tmp_path, capsys):
    """A run trained on other objects (same ids, other names) must not label this dataset's objects."""
    from sixdpose.cli import main

    other = make_run(tmp_path / "other", ClassMap([1, 2, 3], ["obj_000001", "obj_000002", "obj_000003"]))
    rc = main(["segment", "--data", str(toy), "--ckpt", str(other), "--out", str(tmp_path / "pred"), "--no-progress"])
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert "incompatible checkpoint" in err and "\n" not in err
    assert not (tmp_path / "pred").exists()


def test_cli_corrupt_checkpoint_one_line(toy, tmp_path, capsys):
    from sixdpose.cli import main

    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "model.pt").write_bytes(b"\x00" * 100)
    rc = main(["segment", "--data", str(toy), "--ckpt", str(tmp_path / "run"), "--out", str(tmp_path / "p")])
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sixdpose segment: error:") and "corrupt" in err and "\n" not in err


def test_resume_with_corrupt_last_checkpoint(toy, tmp_path):
    from sixdpose.segmentation.train import train

    r = tmp_path / "r"
    train(toy, r, profile="smoke", epochs=1, max_steps_per_epoch=1, val_fraction=0.0, progress=False)
    (r / ck.LAST).write_bytes((r / ck.LAST).read_bytes()[:1000])
    with pytest.raises(ck.CheckpointError, match="corrupt"):
        train(toy, r, resume=True, epochs=2, progress=False)


# -- inference / evaluation edge cases ------------------------------------------------------------
def test_image_without_annotations_and_no_detections(toy, run, tmp_path):
    """Images without annotations are segmented; a run with no detection scores 0 AP, not an error."""
    import yaml

    from sixdpose.artifacts.predictions import prediction_path
    from sixdpose.segmentation.evaluate import evaluate
    from sixdpose.segmentation.infer import segment

    gt = yaml.safe_load((toy / "gt.yml").read_text())
    data = tmp_path / "data"
    import shutil

    shutil.copytree(toy, data)
    gt[0]["objects"] = []
    (data / "gt.yml").write_text(yaml.safe_dump(gt))
    r = segment(data, run, tmp_path / "pred", score_thresh=1.01, progress=False)  # nothing passes
    assert r["images"] == 3 and r["detections"] == 0
    with np.load(prediction_path(tmp_path / "pred", 0, 0)) as p:
        assert p["masks"].shape == (0, 480, 640) and p["masks"].dtype == bool
        assert p["labels"].shape == (0,) and p["scores"].dtype == np.float32
    m = evaluate(data, tmp_path / "pred", tmp_path / "fig")
    assert m["n_images"] == 3 and m["n_det"] == 0
    assert m["overall"]["mask"]["AP"] == 0.0 and m["overall"]["box"]["AP50"] == 0.0


def _perfect_results(gt: dict) -> list[dict]:
    return [{"image_id": a["image_id"], "category_id": a["category_id"], "segmentation": a["segmentation"],
             "bbox": a["bbox"], "score": 0.9} for a in gt["annotations"]]


def test_eval_perfect_and_missing_class(toy, caplog):
    """Perfect predictions give AP 1; a class absent from the images is NaN, logged, out of the mean."""
    from sixdpose.datasets import open_dataset
    from sixdpose.segmentation.evaluate import coco_evaluate, coco_ground_truth

    ds = open_dataset(toy)
    classes = ClassMap.from_dataset(ds)
    classes = ClassMap(classes.obj_ids + [9], classes.names + ["008_pudding_box"])
    gt, stats = coco_ground_truth([ds[i] for i in range(len(ds))], classes)
    assert stats["instances"] == len(gt["annotations"]) > 0
    with caplog.at_level(logging.WARNING, logger="sixdpose"):
        m = coco_evaluate(gt, _perfect_results(gt), classes)
    assert m["overall"]["mask"]["AP"] == pytest.approx(1.0) and m["overall"]["box"]["AP75"] == pytest.approx(1.0)
    row9 = [r for r in m["per_class"] if r["obj_id"] == 9][0]
    assert row9["n_gt"] == 0 and math.isnan(row9["mask_AP"])
    assert "9 (008_pudding_box)" in caplog.text
    present = [r for r in m["per_class"] if r["n_gt"] > 0]
    assert all(r["mask_AP50"] == pytest.approx(1.0) for r in present)


def test_eval_counts_wrong_labels_and_empty_gt_masks(toy):
    """Swapped labels give AP 0; empty GT masks are left out and counted."""
    from sixdpose.datasets import open_dataset
    from sixdpose.segmentation.evaluate import coco_evaluate, coco_ground_truth

    ds = open_dataset(toy)
    classes = ClassMap.from_dataset(ds)
    samples = [ds[i] for i in range(len(ds))]
    samples[0].instances[0].mask[:] = False
    gt, stats = coco_ground_truth(samples, classes)
    assert stats["empty_masks"] == 1
    wrong = _perfect_results(gt)
    for r in wrong:
        r["category_id"] = classes.obj_ids[(classes.obj_ids.index(r["category_id"]) + 1) % len(classes)]
    m = coco_evaluate(gt, wrong, classes)
    assert m["overall"]["mask"]["AP50"] == 0.0


def test_eval_tables(tmp_path):
    from sixdpose.segmentation.evaluate import write_tables

    m = {"per_class": [{"obj_id": 1, "name": "a_b", "n_gt": 2, **{f"{t}_{k}": 0.5 for t in ("mask", "box")
                                                                   for k in ("AP", "AP50", "AP75")}},
                       {"obj_id": 2, "name": "c", "n_gt": 0, **{f"{t}_{k}": math.nan for t in ("mask", "box")
                                                                 for k in ("AP", "AP50", "AP75")}}],
         "overall": {t: {"AP": 0.5, "AP50": 0.5, "AP75": 0.5} for t in ("mask", "box")}, "n_gt": 2}
    csv_path, tex_path = write_tables(m, tmp_path / "figs", tag="_x")
    lines = csv_path.read_text().splitlines()
    assert lines[1] == "1,a_b,2,0.5000,0.5000,0.5000,0.5000,0.5000,0.5000"
    assert lines[2].endswith("nan,nan,nan,nan,nan,nan")
    tex = tex_path.read_text()
    assert r"a\_b & 2 & 50.0" in tex and "c & 0 & -- & --" in tex


def test_eval_rejects_non_prediction_dir(toy, tmp_path):
    from sixdpose.datasets.base import DatasetError
    from sixdpose.segmentation.evaluate import evaluate

    with pytest.raises(DatasetError, match="no meta.json"):
        evaluate(toy, tmp_path)


# -- BOP data ---------------------------------------------------------------------------------------
@pytest.mark.slow
def test_segment_and_eval_bop_sample(tmp_path):
    """On real BOP frames (YCB-V sample): obj ids in the npz, GT from mask_visib, AP computed."""
    from sixdpose.datasets import open_dataset
    from sixdpose.segmentation.evaluate import evaluate
    from sixdpose.segmentation.infer import segment

    root = SHARED / "data" / "ycbv_sample"
    if not root.is_dir():
        pytest.skip("shared ycbv_sample not available")
    ds = open_dataset(root, split="train_real")
    r = make_run(tmp_path / "run", ClassMap.from_dataset(ds))
    out = tmp_path / "pred"
    res = segment(root, r, out, split="train_real", batch_size=8, progress=False)
    assert res["images"] == 40
    for s, i in ds.keys()[:3]:
        with np.load(out / f"{s}_{i}.npz") as z:
            assert z["masks"].shape[1:] == (480, 640)
            assert set(z["labels"].tolist()) <= set(ds.object_ids)
    m = evaluate(root, out, None)
    assert m["n_images"] == 40 and m["n_gt"] > 0
    meta = json.loads((out / "meta.json").read_text())
    assert meta["split"] == "train_real"
