"""The report of notebook 07 (``sixdpose.reporting.report``): tables I-III, per-object tables, the
accuracy curve, Fig. 7 and the write-up's macros, built from result files only; and ``evaluate``'s curve
and ``--limit``."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from sixdpose.artifacts.results import write_result
from sixdpose.reporting import report
from sixdpose.reporting.paper import TABLES


def _res(d, name, acc, *, fps=2.0, curve=True, rows=None, cpu="Test CPU", config=None):
    thr = [0.5 * i for i in range(41)]
    figures = {"accuracy": acc, "mean_object_accuracy": acc - 1, "n_gt": 100, "n_correct": round(acc), "fps": fps,
               "instances_per_s": 4 * fps, "n_images": 10, "n_estimates": 40}
    if curve:
        figures["curve"] = {"threshold_pct": thr, "accuracy": [min(100.0, acc * t / 10) for t in thr]}
    rows = rows or [
        {"obj_id": 1, "name": "055_baseball", "n_gt": 50, "n_correct": 25, "add_s_accuracy": acc - 5},
        {"obj_id": 2, "name": "056_tennis_ball", "n_gt": 50, "n_correct": 25, "add_s_accuracy": acc + 5},
        {"obj_id": "all", "name": "mean over instances", "n_gt": 100, "n_correct": 50, "add_s_accuracy": acc},
        {"obj_id": "objects", "name": "mean over objects", "n_gt": "", "n_correct": "", "add_s_accuracy": acc},
    ]
    p = write_result(name, figures, rows=rows, results_dir=d, command=["sixdpose", "evaluate"], config=config)
    doc = json.loads(p.read_text())  # a machine of our choosing, so the letters are predictable
    doc["provenance"]["hardware"] = {"cpu": cpu, "cpu_count": 2, "cpus_available": 2, "ram_gib": 8.0, "gpus": []}
    p.write_text(json.dumps(doc))
    return p


@pytest.fixture
def results(tmp_path):
    d = tmp_path / "results"
    _res(d, "single_pred_super4pcs", 60.0)
    _res(d, "single_pred_ransac_icp", 50.0, cpu="Other CPU")
    _res(d, "single_pred_learned_it2", 30.0, curve=False)
    _res(d, "single_gt_super4pcs", 80.0)
    _res(d, "test_gt_super4pcs", 70.0)
    _res(d, "test_gt_ransac", 40.0)
    _res(d, "test_gt_ransac_icp", 55.0)
    _res(d, "test_gt_learned_it0", 20.0)
    _res(d, "test_gt_learned_it2", 25.0)
    write_result("pose_ablation_cpu", [{"variant": "paper", "val_add": 3.0}], results_dir=d)  # not a graph result
    return d


def test_names_and_entries(results):
    assert report.parse_name("single_pred_super4pcs") == ("single", "pred", "super4pcs")
    assert report.parse_name("lmo_gt_ransac_icp") == ("lmo", "gt", "ransac_icp")
    for bad in ("pose_ablation_cpu", "test_kinect_gt_ransac_icp", "test_gt_nomethod", "ycbv_gt_ransac_icp"):
        assert report.parse_name(bad) is None
    e = report.load_entries(results)
    assert len(e) == 9 and ("single", "pred", "super4pcs") in e
    assert e[("single", "pred", "learned_it2")].curve is None and e[("test", "gt", "ransac")].curve[0][-1] == 20.0


def test_table3_has_the_papers_column_beside_the_like_for_like_one(results, tmp_path):
    e = report.load_entries(results)
    rows = report.write_table3(e, tmp_path / "t3.csv", tmp_path / "t3.tex")
    s4 = next(r for r in rows if r["method"] == "Super4PCS")
    assert s4["paper"] == TABLES["III"].rows["Ours Hybrid(Super4PCS)"] and s4["single_pred"] == 60.0
    assert s4["single_gt"] == 80.0 and s4["test_gt"] == 70.0 and s4["test_pred"] is None
    assert next(r for r in rows if r["method"] == "Super4PCS + ICP")["paper"] is None  # the paper has no such row
    tex = (tmp_path / "t3.tex").read_text()
    assert "single-instance subset" in tex and "Table III" in tex and "\\cmidrule" in tex
    assert "Super4PCS & 57.32 & 60.00 & 80.00 & -- & 70.00" in tex
    csv = (tmp_path / "t3.csv").read_text().splitlines()
    assert (
        csv[0] == "method,paper,single_pred,single_gt,test_pred,test_gt"
        and "Super4PCS,57.3200,60.0000,80.0000,,70.0000" in csv
    )


def test_table1_without_and_with_lmo(results, tmp_path):
    rows = report.table1(report.load_entries(results))
    assert [r["method"] for r in rows][:2] == ["PoseCNN", "PoseCNN+ICP"] and all(r["lmo_gt"] is None for r in rows)
    _res(results, "lmo_gt_ransac_icp", 33.0)
    _res(results, "lmo_gt_super4pcs_icp", 44.0)
    e = report.load_entries(results)
    rows = report.write_table1(e, tmp_path / "t1.csv", tmp_path / "t1.tex")
    r = next(r for r in rows if r["method"] == "RANSAC + ICP")
    assert r["paper"] == 9.38 and r["lmo_gt"] == 33.0 and r["lmo_pred"] is None
    assert rows[-1]["method"] == "Super4PCS + ICP" and rows[-1]["paper"] is None and rows[-1]["lmo_gt"] == 44.0
    assert "\\iflmo\\lmotrue" in report.macros(e, "cpu")


def test_table2_records_the_machine(results, tmp_path):
    e = report.load_entries(results)
    letters = report.machines(e)
    assert set(letters) == {"Test CPU (2 CPUs, 8 GiB), no GPU", "Other CPU (2 CPUs, 8 GiB), no GPU"}
    rows = report.write_table2(e, tmp_path / "t2.csv", tmp_path / "t2.tex")
    r = next(r for r in rows if r["method"] == "RANSAC + ICP")
    assert r["paper"] == 0.88 and r["fps_gt"] == 2.0 and r["ips_gt"] == 8.0 and r["fps_pred"] is None
    assert r["machine"] == letters["Test CPU (2 CPUs, 8 GiB), no GPU"]
    tex = (tmp_path / "t2.tex").read_text()
    assert "% machine a: Test CPU" in tex and "% machine b: Other CPU" in tex


def test_per_object(results, tmp_path):
    e = report.load_entries(results)
    rows = report.write_per_object(e, "test", "gt", tmp_path / "po.csv", tmp_path / "po.tex")
    assert [r["obj_id"] for r in rows] == [1, 2, "all", "objects"]
    assert rows[0]["ransac"] == 35.0 and rows[1]["super4pcs"] == 75.0 and rows[0]["fgr"] is None
    head = (tmp_path / "po.csv").read_text().splitlines()[0]
    assert head == "obj_id,name,n_gt,ransac,ransac_icp,super4pcs,learned_it0,learned_it2"  # methods that ran only
    report.write_per_object(e, "single", "gt", tmp_path / "e.csv", tmp_path / "e.tex")
    assert report.write_per_object(e, "lmo", "pred", tmp_path / "n.csv", tmp_path / "n.tex") == []
    assert "no results for lmo / pred" in (tmp_path / "n.tex").read_text()


def test_macros_hold_every_number_and_findings(results):
    e = report.load_entries(results)
    text = report.macros(e, "demo", extra={"images@train": "240"})
    assert "\\smallprofiletrue" in text and "\\lmofalse" in text and "\\newcommand{\\profile}{demo}" in text
    assert "\\csname sdp@res@single_pred_super4pcs@acc\\endcsname{60.00}" in text
    assert "\\csname sdp@res@single_pred_super4pcs@ngt\\endcsname{100}" in text
    assert "\\csname sdp@paper@III@super4pcs\\endcsname{57.32}" in text
    assert "\\csname sdp@paper@II@learned_it2\\endcsname{14.97}" in text
    assert "\\csname sdp@best@single@pred@hybrid\\endcsname{Super4PCS}" in text
    assert "\\csname sdp@val@images@train\\endcsname{240}" in text
    f = report.findings(e)
    assert f["finding@setting"].startswith(
        "the best hybrid method (Super4PCS, 60.00 %) is 30.00 points higher than the best learned one"
    )
    assert "(57.32 against 26.87 %)" in f["finding@setting"]
    assert f["finding@repeated"].startswith(
        "ADD(-S) accuracy on the single-instance subset is 10.00 points higher than"
    ) and f["finding@repeated"].endswith("(GT masks)")
    assert "15.00 points higher than" in f["finding@icp"] and "5.00 points higher than" in f["finding@refine"]
    assert f["finding@colour"].startswith("n/a") and f["finding@masks"].startswith(
        "ADD(-S) accuracy with predicted masks is 20.00 points lower"
    )
    assert f["finding@threshold"].startswith("Super4PCS goes from 30.00 % at 5 % of the diameter to 100.00 % at 20 %")
    _res(results, "single_pred_fgr", 60.0)
    _res(results, "single_pred_fgr_icp", 60.0)
    tied = report.load_entries(results)
    assert "\\csname sdp@best@single@pred@hybrid\\endcsname{FGR, FGR + ICP and 1 more (tied)}" in report.macros(
        tied, "cpu"
    )
    assert "\\smallprofilefalse" in report.macros(e, "cpu")
    assert "\\lmofalse" in report.macros({}, "paper")  # no results at all still gives a usable file


def test_curves_fig7_and_dataset_table(results, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    e = report.load_entries(results)
    fig = report.plot_curves(e)
    assert len(fig.axes) == 4
    texts = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert any("no curve recorded: learned + 2 refinement it." in t for t in texts)
    fig, why = report.draw_fig7(e, "test_gt_learned_it2", tmp_path)
    assert "config names no dataset" in why and fig is not None
    fig, why = report.draw_fig7(e, "single_gt_learned_it0", tmp_path)
    assert why == "no result single_gt_learned_it0 among the evaluations"
    stats = tmp_path / "dataset_statistics.csv"
    stats.write_text("quantity,paper,this dataset\nimages,\"25,000\",240\ntargets per scene,5-20,5-20 (mean 12.1)\n")
    report.dataset_table(stats, tmp_path / "ds.tex")
    tex = (tmp_path / "ds.tex").read_text()
    assert "images & 25,000 & 240 \\\\" in tex and "p{0.34\\linewidth}" in tex
    with pytest.raises(report.ReportError, match=r"missing\.csv: cannot read the dataset statistics"):
        report.dataset_table(tmp_path / "missing.csv", tmp_path / "x.tex")
    vals = report.dataset_values(e, tmp_path, None)
    assert vals == {
        "images@test": "n/a",
        "seed@test": "n/a",
        "images@single": "n/a",
        "seed@single": "n/a",
        "images@train": "n/a",
    }
    (tmp_path / "train").mkdir()
    (tmp_path / "train" / "manifest.json").write_text(json.dumps({"num_images": 1200}))
    assert report.dataset_values(e, tmp_path, tmp_path / "train")["images@train"] == "1,200 images"
    assert "\\csname sdp@val@images@train\\endcsname{1,200 images}" in report.macros(
        e, "cpu", extra=report.dataset_values(e, tmp_path, tmp_path / "train")
    )  # a thousands comma, not an escaped {,}


# --------------------------------------------------------------------------------------------
# evaluate: the accuracy curve, --limit, and Fig. 7 from a real results CSV
# --------------------------------------------------------------------------------------------
def test_evaluate_curve_limit_and_fig7(tmp_path, capsys):
    import matplotlib

    matplotlib.use("Agg")
    from sixdpose.artifacts.poses import PoseEstimate, write_results
    from sixdpose.cli import main
    from sixdpose.datasets import open_dataset
    from sixdpose.evaluation.evaluate import CURVE_THRESHOLDS_PCT, evaluate
    from test_reg_helpers import write_synthetic_dataset

    syn = write_synthetic_dataset(tmp_path / "syn", n_images=3)
    ds = open_dataset(syn)
    diam = ds.model(15).diameter
    rows = []
    for k, s in enumerate(ds[i] for i in range(3)):
        for j, g in enumerate(s.instances):
            off = diam * (0.03 if (k, j) == (0, 0) else 0.15 if k == 1 else 0.0)  # one at 3 %, one at 15 %
            rows.append(PoseEstimate(s.scene_id, s.im_id, g.obj_id, 1.0, g.R, g.t + np.array([off, 0, 0]), 0.5))
    res = evaluate(ds, rows, min_px=0)
    acc = dict(zip(res.curve["threshold_pct"], res.curve["accuracy"], strict=True))
    assert res.curve["threshold_pct"] == list(CURVE_THRESHOLDS_PCT)
    assert acc[10.0] == pytest.approx(res.accuracy) and res.accuracy == pytest.approx(75.0)  # 3 of 4 instances
    assert (
        acc[0.0] == 0.0 and acc[2.5] == pytest.approx(50.0) and acc[5.0] == pytest.approx(75.0) and acc[20.0] == 100.0
    )
    write_results(rows, tmp_path / "r.csv")
    base = ["evaluate", "--data", str(syn), "--results", str(tmp_path / "r.csv"), "--min-px", "0", "--no-bop",
            "--results-dir", str(tmp_path / "results")]
    assert main(base + ["--limit", "1", "--result-name", "test_gt_learned_it2", "--out", str(tmp_path / "ev1")]) == 0
    e = report.load_entries(tmp_path / "results")[("test", "gt", "learned_it2")]
    assert e.figure("n_gt") == 2 and e.result.config["limit"] == 1 and e.curve[1][-1] == 100.0
    assert main(base + ["--limit", "-1", "--out", str(tmp_path / "ev2")]) == 2
    assert "argument --limit: -1 is out of range: expected an integer >= 0" in capsys.readouterr().err
    fig, why = report.fig7(e, root="/")
    assert why is None and fig is not None and math.isfinite(e.figure("accuracy"))


# --------------------------------------------------------------------------------------------
# the generator leaves a complete dataset untouched (make sees nothing new)
# --------------------------------------------------------------------------------------------
def test_write_if_changed(tmp_path):
    import os

    from sixdpose.fileio import write_if_changed

    p = tmp_path / "m.json"
    assert write_if_changed(p, "a") and p.read_text() == "a"
    os.utime(p, (1, 1))
    assert not write_if_changed(p, "a") and p.stat().st_mtime == 1
    assert write_if_changed(p, b"b") and p.read_text() == "b" and p.stat().st_mtime > 1
    assert re.fullmatch(r"[ab]", p.read_text())


def test_real_frames_and_ablation_tables(tmp_path):
    """The synthetic-to-real rows (``ycbv_gt_*``) and the ablation (``pose_ablation_<profile>``) as tables
    and sentences; without their result files, one row and an n/a sentence say so."""
    d = tmp_path / "results"
    d.mkdir()
    assert report.real_table(d) == [] and report.ablation_table(d, "cpu") == []
    rows = report.write_real_table(d, tmp_path / "r.csv", tmp_path / "r.tex")
    assert rows == [] and "not run at this profile" in (tmp_path / "r.tex").read_text()
    f = report.beyond_findings(d, "cpu")
    assert set(f) == {"finding@real", "finding@sensor", "finding@ablation", "finding@ablation_seeds",
                      "finding@fps_e2e"}
    assert f["finding@sensor"] == "" and "has not run the ablation over seeds" in f["finding@ablation_seeds"]
    assert "does not run that branch" in f["finding@real"] and "has not run the ablation" in f["finding@ablation"]
    for name, acc, auc in (("ycbv_gt_learned", 36.0, 85.0), ("ycbv_gt_learned_ideal", 36.0, 76.0),
                           ("ycbv_gt_learned_colour", 75.0, 90.0), ("ycbv_gt_super4pcs_icp", 90.0, 97.0)):
        write_result(name, {"accuracy": acc, "n_gt": 140, "bop": {"ar": 5.0, "adds_auc": auc}}, results_dir=d)
    write_result(
        "pose_ablation_cpu",
        [
            {"variant": "paper (absolute t, quaternion, no norm)", "val_add": 3.0, "steps": 300},
            {"variant": "+ centroid offset", "val_add": 14.0, "steps": 300},
        ],
        results_dir=d,
    )
    rows = report.write_real_table(d, tmp_path / "r.csv", tmp_path / "r.tex")
    assert [(r["method"], r["trained_on"]) for r in rows] == [
        ("learned", "ycbv (kinect depth)"), ("learned", "ycbv_ideal (ideal depth)"),
        ("learned + colour verification", "ycbv (kinect depth)"), ("Super4PCS + ICP", "--")]
    assert rows[0]["adds_auc"] == 85.0
    f = report.beyond_findings(d, "cpu")
    assert (
        "36.00 % ADD(-S) on 140 real instances, and 75.00 %" in f["finding@real"]
        and "90.00 % (Super4PCS + ICP)" in f["finding@real"]
    )
    assert "equal to the same network trained on ideal depth" in f["finding@sensor"]
    assert "9.00 points higher than the ideal-depth network's" in f["finding@sensor"]
    assert "refinement" not in f["finding@sensor"]  # no refined pair: no sentence about it
    for name, acc in (("ycbv_gt_learned_it2", 30.0), ("ycbv_gt_learned_ideal_it2", 42.86),
                      ("ycbv_gt_learned_ideal_colour", 50.0)):
        write_result(name, {"accuracy": acc, "n_gt": 140}, results_dir=d)
    f = report.beyond_findings(d, "cpu")
    assert ("Kinect against ideal depth in the other pairs (both networks of a pair trained alike, the same stage "
            "after both): 30.00 % after 2 refinement iterations (each network with its own refiner), "
            "12.86 points lower than the ideal-depth pair (42.86 %); 75.00 % after colour verification, 25.00 points "
            "higher than the ideal-depth pair (50.00 %).") in f["finding@sensor"]
    assert "after ICP" not in f["finding@sensor"]  # only one of the ICP pair exists
    rows = report.real_table(d)
    assert [r["trained_on"] for r in rows if r["method"] == "learned + colour verification"] == [
        "ycbv (kinect depth)", "ycbv_ideal (ideal depth)"]
    assert f["finding@ablation"].startswith(
        "The best of 2 variants on the validation split is + centroid offset (14.00 %)"
    )
    assert "paper's choices reach 3.00 %" in f["finding@ablation"]
    abl = report.write_ablation_table(d, "cpu", tmp_path / "a.csv", tmp_path / "a.tex")
    assert [r["val_add"] for r in abl] == [3.0, 14.0] and "centroid offset" in (tmp_path / "a.tex").read_text()
    assert [(r["network"], r["seeds"]) for r in abl] == [("pose", 1), ("pose", 1)]  # a one-seed result's defaults
    write_result("pose_ablation_seeds_cpu", [
        {"variant": "+ centroid offset", "network": "pose", "val_add": 14.0, "val_add_std": 1.5, "seeds": 3},
        {"variant": "refiner trained without noise", "network": "refiner", "val_add": 20.0, "val_add_std": 2.0,
         "seeds": 3}], results_dir=d)
    f = report.beyond_findings(d, "cpu")
    assert f["finding@ablation_seeds"] == ("Over 3 seeds: + centroid offset 14.00 +- 1.50 %; refiner trained without "
                                           "noise 20.00 +- 2.00 %.")
    abl = report.write_ablation_table(d, "cpu", tmp_path / "s.csv", tmp_path / "s.tex", name="pose_ablation_seeds")
    assert [r["val_add_std"] for r in abl] == [1.5, 2.0] and "refiner" in (tmp_path / "s.tex").read_text()


def test_paper_settings_rows_appear_only_with_their_results(results, tmp_path):
    e = report.load_entries(results)
    labels = [r["method"] for r in report.table3(e)]
    assert not any("paper settings" in x for x in labels)  # no rerun result: no row
    assert report.findings(e)["finding@paper_settings"].startswith("n/a")
    _res(results, "single_pred_super4pcs_paper", 45.0)
    _res(results, "test_gt_ransac_icp_paper", 52.0, fps=0.5)
    e = report.load_entries(results)
    t3 = report.table3(e)
    labels = [r["method"] for r in t3]
    # the rows with the paper's settings stand right after ours, before the learned rows
    assert labels.index("Super4PCS (paper settings, rerun)") < labels.index("learned, no refinement")
    row = next(r for r in t3 if r["method"] == "Super4PCS (paper settings, rerun)")
    assert row["single_pred"] == 45.0 and row["test_gt"] is None and row["paper"] is None
    assert "RANSAC + ICP (paper settings, rerun)" in labels and "FGR + ICP (paper settings, rerun)" not in labels
    t2 = report.table2(e)
    assert [r["fps_gt"] for r in t2 if r["method"] == "RANSAC + ICP (paper settings, rerun)"] == [0.5]
    assert not any(r["method"] == "Super4PCS (paper settings, rerun)" for r in t2)  # no test-split result
    # the best hybrid method of the write-up stays ours; the rerun's change against ours is a sentence
    assert report._best(e, "single", "pred", "hybrid")[0].key == "super4pcs"
    s = report.findings(e)["finding@paper_settings"]
    assert "on average over 2 methods" in s and "lower than" in s and "-15.00 points" in s
    report.write_table3(e, tmp_path / "t3.csv", tmp_path / "t3.tex")
    assert "Super4PCS (paper settings, rerun)" in (tmp_path / "t3.tex").read_text()


def test_table2_end_to_end_from_the_benchmark_result(tmp_path):
    d = tmp_path / "results"
    rows = report.write_table2_e2e(d, tmp_path / "t.csv", tmp_path / "t.tex")
    assert rows == [] and "not run" in (tmp_path / "t.tex").read_text()
    assert "has not run" in report.beyond_findings(d, "cpu")["finding@fps_e2e"]
    bench = [{"method": "ransac_icp", "command": "register --method ransac --icp", "frames": 4, "instances": 10,
              "e2e_fps": 0.25, "pose_fps": 1.5, "seg_ms_per_frame": 2500.0, "e2e_ms_per_frame": 4000.0,
              "pose_ms_per_frame": 666.0},
             {"method": "learned_it2", "command": "predict-pose", "frames": 4, "instances": 10, "e2e_fps": 0.3,
              "pose_fps": 2.0, "seg_ms_per_frame": 2600.0, "e2e_ms_per_frame": 3300.0, "pose_ms_per_frame": 500.0}]
    write_result(report.TABLE2_BENCH, bench, results_dir=d,
                 config={"data": "../shared/data/ycbv_sample", "split": "train_real", "segmentation": "untrained",
                         "pose": "untrained paper networks", "preset": "default"})
    rows = report.write_table2_e2e(d, tmp_path / "t.csv", tmp_path / "t.tex")
    assert [r["method"] for r in rows] == ["RANSAC + ICP", "learned + 2 refinement it."]
    assert rows[0]["paper"] == TABLES["II"].rows["Ours Hybrid(RANSAC + ICP)"] and rows[0]["instances"] == 2.5
    assert rows[1]["e2e_fps"] == 0.3 and rows[1]["pose_fps"] == 2.0
    assert "RANSAC + ICP & " in (tmp_path / "t.tex").read_text()
    note = report.beyond_findings(d, "cpu")["finding@fps_e2e"]
    assert note.startswith("Measured by benchmarks/table2_fps.py on 4 frames of ycbv_sample (train_real)")
    write_result(report.TABLE2_BENCH, [{"method": "nonsense", "frames": 1}], results_dir=d)
    with pytest.raises(report.ReportError, match="table2_fps.json: method 'nonsense'"):
        report.table2_e2e(d)


# --------------------------------------------------------------------------------------------
# the write-up where the datasets are not here (make tables on the committed results), the charts
# --------------------------------------------------------------------------------------------
def test_dataset_values_and_table_kept_where_the_datasets_are_not_here(results, tmp_path):
    e = report.load_entries(results)
    macros = tmp_path / "macros.tex"
    report.write_macros(e, "cpu", macros, extra={"images@train": "1,200 images", "seed@test": "300",
                                                 "images@single": "a_b"})
    values = report.dataset_values(e, tmp_path, tmp_path / "no_data")
    assert values["images@train"] == "n/a" and values["seed@test"] == "n/a"
    kept_values, kept = report.keep_known(values, macros)
    assert kept_values["images@train"] == "1,200 images" and kept_values["seed@test"] == "300"
    # a value LaTeX escaping would change is not carried over (it would be escaped twice)
    assert "images@single" not in kept and kept_values["images@single"] == "n/a"
    assert report.keep_known(values, tmp_path / "none.tex") == (values, [])
    tex = tmp_path / "table_dataset.tex"
    line = report.write_dataset_table(tmp_path / "stats.csv", tex, "make nb02")
    assert "not computed" in line and "not computed: make nb02" in tex.read_text()
    (tmp_path / "stats.csv").write_text("quantity,paper,this dataset\nimages,\"25,000\",6\n")
    assert "from" in report.write_dataset_table(tmp_path / "stats.csv", tex, "make nb02")
    text = tex.read_text()
    assert "25,000" in text
    (tmp_path / "stats.csv").unlink()
    assert "kept" in report.write_dataset_table(tmp_path / "stats.csv", tex, "make nb02") and tex.read_text() == text


def test_shape_summary_counts_only(results):
    e = report.load_entries(results)
    text = report.shape_summary(e, {"Table III": report.table3(e), "empty": []})
    assert text.splitlines()[0] == "9 evaluations"
    assert "  single/pred: 3 (learned_it2, ransac_icp, super4pcs)" in text
    assert re.search(r"^Table III: \d+ rows x 6 columns, \d+ cells filled$", text, re.M)
    assert "empty: 0 rows x 0 columns, 0 cells filled" in text
    assert not re.search(r"\d+\.\d", text)  # no figure, only counts


def test_charts_from_results_alone(results, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    from sixdpose.reporting import charts

    e = report.load_entries(results)
    figs = tmp_path / "figs"
    written, skipped = charts.write_charts(e, results, "cpu", figs)
    assert {"table3.png", "table2_fps.png", "per_object_test_gt.png", "per_object_single_pred.png"} <= set(written)
    assert sorted(p.name for p in figs.iterdir()) == sorted(written)
    assert "real_frames.png" in skipped and "ablation.png" in written  # no real-frame result; the ablation ran
    first = (figs / "table3.png").read_bytes()
    charts.write_charts(e, results, "cpu", figs)
    assert (figs / "table3.png").read_bytes() == first  # the same results, the same bytes
    assert b"Matplotlib" not in first
    assert charts.plot_table3([]) is None and charts.plot_per_object([]) is None and charts.plot_real([]) is None


def test_speed_accuracy_chart_pairs_a_methods_rows_with_and_without_verification():
    """The verification benchmark's chart: one marker per row with both numbers, an arrow per method from
    its row with verification off to its row with it on; nothing to draw gives None."""
    import matplotlib

    matplotlib.use("Agg")
    from sixdpose.reporting import charts

    rows = [{"method": "A", "verify": "off", "accuracy": 90.0, "inst_per_s": 2.0},
            {"method": "A", "verify": "on", "accuracy": 95.0, "inst_per_s": 1.5},
            {"method": "B", "verify": "off", "accuracy": 80.0, "inst_per_s": 9.0},
            {"method": "C", "verify": "on", "accuracy": None, "inst_per_s": 3.0}]  # no accuracy: left out
    fig = charts.plot_speed_accuracy(rows)
    ax = fig.axes[0]
    assert len(ax.collections) == 3  # A off, A on, B off
    arrows = [t for t in ax.texts if getattr(t, "arrow_patch", None) is not None]
    assert len(arrows) == 1 and tuple(arrows[0].xy) == (1.5, 95.0)  # A: off -> on
    assert charts.plot_speed_accuracy(rows[3:]) is None and charts.plot_speed_accuracy([]) is None
    # a row measured several times is drawn at its median speed
    fig = charts.plot_speed_accuracy([{"method": "D", "verify": "on", "accuracy": 97.0, "inst_per_s": 8.0,
                                       "inst_per_s_median": 7.0}])
    assert tuple(fig.axes[0].collections[0].get_offsets()[0]) == (7.0, 97.0)


def test_hybrid_methods_name_the_verification_rows():
    """compare.hybrid_methods(verify=(False, True)) gives each combination its own row name."""
    from sixdpose.reporting.compare import hybrid_methods

    methods = hybrid_methods(methods=("super4pcs",), icp=(True,), verify=(False, True))
    assert list(methods) == ["Hybrid (Super4PCS + ICP)", "Hybrid (Super4PCS + ICP + verification)"]
    # each run is bound to its configuration (the last default of the closure): verify on in the second only
    assert [run.__defaults__[-1].verify for run in methods.values()] == [False, True]
    assert list(hybrid_methods(methods=("ransac",), icp=(False,))) == ["Hybrid (RANSAC)"]
