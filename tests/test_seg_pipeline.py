"""End-to-end segmentation stage: smoke training overfits a tiny dataset, segment writes the agreed
prediction format, evaluation reports AP (acceptance test of the issue)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("pycocotools")


@pytest.fixture(scope="module")
def seg_data(request, tmp_path_factory):
    """The generated ``tiny_dataset`` (smoke profile); a toy shapes dataset if it cannot be made."""
    try:
        return request.getfixturevalue("tiny_dataset")
    except (pytest.FixtureLookupError, pytest.skip.Exception):  # no fixture / no YCB assets
        from sixdpose.segmentation.toydata import make_toy_dataset

        return make_toy_dataset(tmp_path_factory.mktemp("seg_toy") / "toy", n_scenes=2, views=3, seed=0)


@pytest.fixture(scope="module")
def trained(seg_data, tmp_path_factory):
    """A smoke-profile run trained on ``seg_data`` (shared by the tests of this module)."""
    from sixdpose.segmentation.train import train

    run = tmp_path_factory.mktemp("seg_run") / "run"
    summary = train(seg_data, run, profile="smoke", progress=False)
    return run, summary


@pytest.fixture(scope="module")
def predicted(seg_data, trained, tmp_path_factory):
    """``segment`` output of the run on its own training images."""
    from sixdpose.segmentation.infer import segment

    out = tmp_path_factory.mktemp("seg_pred") / "pred"
    r = segment(seg_data, trained[0], out, subset="train", batch_size=2, progress=False)
    return out, r


@pytest.mark.slow
def test_smoke_training_loss_falls(trained):
    from sixdpose.segmentation.train import read_metrics

    run, summary = trained
    assert summary["init"] == "random"  # smoke never looks for (or downloads) weights
    rows = read_metrics(run)
    assert rows[0]["epoch"] == 0 and rows[-1]["epoch"] == summary["epochs"] - 1
    n = max(3, len(rows) // 5)
    first = np.mean([r["loss"] for r in rows[:n]])
    last = np.mean([r["loss"] for r in rows[-n:]])
    assert last < 0.5 * first, (first, last)
    for name in ("config.json", "split.json", "run.json", "metrics.csv", "last.pt", "model.pt", "manifest.json"):
        assert (run / name).is_file(), name
    split = json.loads((run / "split.json").read_text())
    assert split["train"]["keys"] and split["test"]["keys"]  # seeded 90/10 split of the synthetic layout
    assert not set(map(tuple, split["train"]["keys"])) & set(map(tuple, split["test"]["keys"]))


@pytest.mark.slow
def test_overfits_training_images(seg_data, predicted, tmp_path):
    """Acceptance: mask AP50 >= 0.5 on the run's own training images."""
    from sixdpose.segmentation.evaluate import evaluate

    out, r = predicted
    m = evaluate(seg_data, out, tmp_path / "figures", tag="_overfit")
    print("overfit:", json.dumps(m["overall"]), f"{r['images_per_s']:.2f} images/s")
    assert m["overall"]["mask"]["AP50"] >= 0.5, m["overall"]
    assert m["overall"]["box"]["AP50"] >= 0.5, m["overall"]
    csv_text = (tmp_path / "figures" / "seg_ap_overfit.csv").read_text().splitlines()
    assert csv_text[0].startswith("obj_id,name,n_gt,mask_AP,mask_AP50,mask_AP75,box_AP")
    assert csv_text[-1].split(",")[1] == "all"
    tex = (tmp_path / "figures" / "seg_ap_overfit.tex").read_text()
    assert r"\begin{tabular}" in tex and "all" in tex


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # pycocotools' decode under numpy 2
def test_segment_output_format(seg_data, trained, predicted):
    """The npz files are what the registration stage reads (see the package docstring)."""
    from sixdpose.artifacts.predictions import prediction_path, read_predictions
    from sixdpose.datasets import open_dataset

    out, r = predicted
    split = json.loads((trained[0] / "split.json").read_text())
    keys = [tuple(k) for k in split["train"]["keys"]]
    assert r["images"] == len(keys)
    ds = open_dataset(seg_data)
    ids = set(ds.object_ids)
    samples = {k: ds[i] for i, k in enumerate(ds.keys())}
    for s, i in keys:
        path = prediction_path(out, s, i)
        assert path.name == f"{s}_{i}.npz" and path.is_file()
        with np.load(path) as z:
            assert sorted(z.files) == ["boxes", "labels", "masks", "scores"]
            masks, labels, scores = z["masks"], z["labels"], z["scores"]
        H, W = samples[(s, i)].rgb.shape[:2]
        assert masks.dtype == bool and masks.shape[1:] == (H, W) and masks.shape[0] == len(labels) == len(scores)
        assert np.issubdtype(labels.dtype, np.integer) and scores.dtype == np.float32
        assert set(labels.tolist()) <= ids  # dataset obj ids, not class indices
        assert np.all(np.diff(scores) <= 0) and np.all((scores >= 0) & (scores <= 1))
        dets = read_predictions(out, s, i)
        assert len(dets) == len(masks) and all(np.array_equal(d.mask, m) for d, m in zip(dets, masks, strict=True))
    res = json.loads((out / "coco_results.json").read_text())
    assert len(res) == sum(len(read_predictions(out, s, i)) for s, i in keys)
    from pycocotools import mask as mask_util

    if res:
        d = res[0]
        assert {"image_id", "category_id", "segmentation", "bbox", "score"} <= set(d)
        m = mask_util.decode({"size": d["segmentation"]["size"], "counts": d["segmentation"]["counts"].encode()})
        assert m.shape == tuple(d["segmentation"]["size"])
    meta = json.loads((out / "meta.json").read_text())
    assert [tuple(x[:2]) for x in meta["images"]] == keys


@pytest.mark.slow
def test_cli_segment_and_eval(seg_data, trained, tmp_path, capsys):
    """The console commands on the trained run (test images, GPU if present, else CPU)."""
    from sixdpose.cli import main

    pred = tmp_path / "pred"
    rc = main(["segment", "--data", str(seg_data), "--ckpt", str(trained[0]), "--out", str(pred),
               "--subset", "test", "--no-progress"])
    assert rc == 0
    assert "segmented" in capsys.readouterr().out
    rc = main(["eval-seg", "--data", str(seg_data), "--pred", str(pred), "--figures", str(tmp_path / "fig")])
    assert rc == 0
    out = capsys.readouterr().out
    assert "mask AP" in out and (tmp_path / "fig" / "seg_ap.csv").is_file()


@pytest.mark.slow
def test_segmenter_batched_equals_single(seg_data, trained):
    """Batching does not change the predictions."""
    from sixdpose.datasets import open_dataset
    from sixdpose.segmentation import Segmenter

    seg = Segmenter(trained[0], device="cpu")
    ds = open_dataset(seg_data)
    rgbs = [ds[0].rgb, ds[1].rgb]
    both = seg.predict(rgbs)
    one = [seg.predict([r])[0] for r in rgbs]
    for a, b in zip(both, one, strict=True):
        assert np.array_equal(a["labels"], b["labels"])
        assert np.allclose(a["scores"], b["scores"], atol=1e-4)
        if len(a["labels"]):
            inter = (a["masks"] & b["masks"]).sum()
            union = (a["masks"] | b["masks"]).sum()
            assert inter / max(union, 1) > 0.99
    assert not math.isnan(float(seg.cfg.score_thresh))


def test_segmenter_compiles_its_backbone_on_the_cpu_without_changing_the_masks(seg_data, trained):
    """On the CPU the Segmenter runs a compiled backbone unless told not to; the predictions are the eager ones."""
    from sixdpose.datasets import open_dataset
    from sixdpose.segmentation import Segmenter

    fast, eager = Segmenter(trained[0], device="cpu"), Segmenter(trained[0], device="cpu", optimise=False)
    assert fast.optimised and not eager.optimised
    rgbs = [s.rgb for s in list(open_dataset(seg_data))[:3]]
    for a, b in zip(fast.predict(rgbs), eager.predict(rgbs), strict=True):
        assert np.array_equal(a["labels"], b["labels"])
        assert np.allclose(a["scores"], b["scores"], atol=1e-4)
        assert a["masks"].shape == b["masks"].shape
        assert (a["masks"] != b["masks"]).sum() <= 0.001 * max(a["masks"].size, 1)


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_hybrid_runner_reads_segment_output(seg_data, trained, predicted, tmp_path):
    """``sixdpose register --masks PRED_DIR`` consumes what ``segment`` wrote: one row per detection
    at or above --min-score, on the images segment covered."""
    from sixdpose.artifacts.predictions import read_predictions
    from sixdpose.cli import main

    out, _ = predicted
    keys = [tuple(k) for k in json.loads((trained[0] / "split.json").read_text())["train"]["keys"]]
    expected = 0
    for s, i in keys:
        dets = read_predictions(out, s, i)
        expected += sum(d.score >= 0.3 for d in dets)
    csv = tmp_path / "pred_rows.csv"
    assert main(["register", "--data", str(seg_data), "--method", "fgr", "--masks", str(out), "--min-score", "0.3",
                 "--out", str(csv), "--workers", "1", "--no-progress"]) == 0
    rows = csv.read_text().strip().splitlines()[1:]
    assert len(rows) == expected and expected > 0
    assert {(int(r.split(",")[0]), int(r.split(",")[1])) for r in rows} <= set(keys)


@pytest.mark.slow
def test_the_backbone_benchmark_scores_held_out_images_and_times_them(seg_data, trained, tmp_path, capsys):
    """benchmarks/seg_backbones.py: one row per run with its held-out images' AP and its time per image; the
    result artifact is written; a directory that is not a run, or --frames 0, is refused with exit status 2."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "seg_backbones.py"
    spec = importlib.util.spec_from_file_location("seg_backbones", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    run = str(trained[0])
    args = ["--runs", run, "--data", str(seg_data), "--time-data", str(seg_data), "--frames", "2",
            "--results-dir", str(tmp_path), "--result-name", "seg_bb"]
    assert bench.main(args) == 0
    rows = json.loads((tmp_path / "seg_bb.json").read_text())["rows"]
    split = json.loads((trained[0] / "split.json").read_text())
    assert len(rows) == 1 and rows[0]["backbone"] == "resnet18" and rows[0]["timed_images"] == 2
    assert rows[0]["held_out_images"] == len(split["test"]["keys"])
    assert 0 <= rows[0]["mask_ap"] <= 100 and rows[0]["ms_per_image"] > 0 and rows[0]["params_m"] > 0
    assert bench.main(["--runs", str(tmp_path), "--no-result"]) == 2
    assert "not a segmentation run" in capsys.readouterr().err
    with pytest.raises(SystemExit) as bad:
        bench.main(["--runs", run, "--frames", "0", "--no-result"])
    assert bad.value.code == 2 and "--frames: 0 is out of range" in capsys.readouterr().err


def test_the_compile_benchmark_times_both_variants_and_finds_the_same_detections(seg_data, trained, tmp_path):
    """benchmarks/seg_compile.py: an eager and a compiled row, end to end with an (untrained) dense head, the
    detections found the same; the result artifact is written; --passes 0 is refused with exit status 2."""
    import importlib.util
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "benchmarks"
    mods = {}
    for name in ("seg_compile", "pose"):
        spec = importlib.util.spec_from_file_location(f"bench_{name}", root / f"{name}.py")
        mods[name] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mods[name])
    pose, _ = mods["pose"].fake_runs("smoke", tmp_path, classes=16, head="dense", appearance="local")
    args = ["--seg", str(trained[0]), "--pose", str(pose), "--data", str(seg_data), "--frames", "2",
            "--passes", "2", "--results-dir", str(tmp_path), "--result-name", "seg_cmp"]
    assert mods["seg_compile"].main(args) == 0
    rows = json.loads((tmp_path / "seg_cmp.json").read_text())["rows"]
    assert [r["variant"] for r in rows] == ["eager", "compiled"]
    for r in rows:
        assert r["same_detections"] is True and r["passes"] == 2 and r["frames"] == 2
        assert r["seg_ms"] > 0 and r["pose_ms"] > 0 and r["e2e_fps_min"] <= r["e2e_fps_max"]
        assert r["e2e_fps"] == pytest.approx(1000 / (r["seg_ms"] + r["pose_ms"]))
    with pytest.raises(SystemExit) as bad:
        mods["seg_compile"].main(args[:-6] + ["--passes", "0", "--no-result"])
    assert bad.value.code == 2
