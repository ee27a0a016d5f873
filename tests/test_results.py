"""Result artifacts (``results/*.json``): the writer and reader, the commands that write them, and the
README blocks generated from them (the first test fails when the README and ``results/`` disagree)."""

from __future__ import annotations

import datetime as dt
import importlib.util
import json
import re
import socket
from pathlib import Path

import numpy as np
import pytest

from sixdpose.artifacts.results import ResultError, read_result, write_result
from sixdpose.reporting.readme import BLOCKS, default_pages, render_block, stale_blocks
from sixdpose.reporting.readme import main as readme_main

REPO = Path(__file__).resolve().parents[1]


# --------------------------------------------------------------------------------------------
# the README's generated tables are what results/ generates
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("page", [p.relative_to(REPO) for p in default_pages(REPO)], ids=str)
def test_readme_blocks_match_results(page):
    """The generated blocks of the README and of the pages of docs/ are what results/ generates."""
    stale = stale_blocks(REPO / page, REPO / "results")
    assert stale == [], f"{page}: blocks {stale} differ from results/: run `make results-readme`"


def test_the_readme_and_docs_hold_generated_blocks():
    pages = default_pages(REPO)
    assert REPO / "README.md" in pages and len(pages) > 5
    assert "<!-- results:" in (REPO / "README.md").read_text(), "README.md has no generated result blocks"
    # every curated block is shown somewhere
    text = "".join(p.read_text() for p in pages)
    assert all(f"<!-- results:{name} -->" in text for name in BLOCKS)


def test_every_result_file_reads():
    paths = sorted((REPO / "results").rglob("*.json"))
    assert paths, "results/ has no result file"
    for p in paths:
        r = read_result(p)
        assert r.provenance["date"].endswith("Z") and r.provenance["command"], p


# --------------------------------------------------------------------------------------------
# writer and reader
# --------------------------------------------------------------------------------------------
def test_round_trip_provenance_and_csv(tmp_path):
    inp = tmp_path / "in.csv"
    inp.write_text("a,b\n1,2\n")
    p = write_result(
        "bench_x",
        {"acc": 93.5, "missing": float("nan"), "n": np.int64(7), "v": np.float32(0.5)},
        rows=[{"method": "ransac", "ips": np.float64(10.4)}, {"method": "fgr", "ips": float("inf"), "extra": [1, 2]}],
        units={"acc": "%", "ips": "instances/s"},
        description="a test",
        results_dir=tmp_path / "res",
        command=["python", "benchmarks/x.py", "--stride", "5"],
        config={"stride": 5},
        inputs=[inp],
        notes="n",
    )
    assert p == tmp_path / "res" / "bench_x.json"
    r = read_result("bench_x", tmp_path / "res")
    assert r.figures == {"acc": 93.5, "missing": None, "n": 7, "v": 0.5}
    assert r.rows == [{"method": "ransac", "ips": 10.4}, {"method": "fgr", "ips": None, "extra": [1, 2]}]
    assert r.row(method="fgr")["extra"] == [1, 2] and r.column("method") == ["ransac", "fgr"]
    assert r.units["ips"] == "instances/s" and r.config == {"stride": 5} and r.notes == "n"
    assert r.inputs[0]["bytes"] == 8 and len(r.inputs[0]["sha256"]) == 64
    prov = r.provenance
    assert prov["command"] == ["python", "benchmarks/x.py", "--stride", "5"]
    assert prov["commit"] is None or re.fullmatch(r"[0-9a-f]{40}", prov["commit"])
    assert prov["dirty"] in (True, False, None)
    when = dt.datetime.fromisoformat(prov["date"].replace("Z", "+00:00"))
    assert abs((dt.datetime.now(dt.UTC) - when).total_seconds()) < 120
    hw = prov["hardware"]
    assert hw["cpu"] and hw["cpu_count"] >= 1 and isinstance(hw["gpus"], list) and "ram_gib" in hw
    text = p.read_text()
    host = socket.gethostname()
    if len(host) >= 4:
        assert host not in text
    assert "NaN" not in text and "Infinity" not in text  # strict JSON
    assert (tmp_path / "res" / "bench_x.csv").read_text().splitlines()[:2] == ["method,ips,extra", "ransac,10.4,"]
    write_result("dup", [{"a": 1}, {"a": 1}], results_dir=tmp_path)
    with pytest.raises(ResultError, match="dup.json: 2 rows match"):
        read_result("dup", tmp_path).row(a=1)


def test_table_only_result_and_default_command(tmp_path):
    write_result("t", [{"a": 1}], results_dir=tmp_path, csv_table=False)
    r = read_result(tmp_path / "t.json")
    assert r.rows == [{"a": 1}] and r.figures == {} and not (tmp_path / "t.csv").exists()
    assert r.provenance["command"]  # sys.argv of pytest, its program shortened


def test_earlier_rows_are_the_runs_not_measured_again(tmp_path):
    """A benchmark's --keep (sixdpose.artifacts.results.earlier_rows): the rows of the file already there
    whose run is not among the new rows, as copies; none without a file; a corrupt file is refused."""
    from sixdpose.artifacts.results import earlier_rows

    assert earlier_rows("k", [{"run": "a"}], results_dir=tmp_path) == []
    write_result("k", [{"run": "a", "x": 1}, {"run": "b", "x": 2}, {"run": "c", "x": 3}], results_dir=tmp_path)
    kept = earlier_rows("k", [{"run": "b", "x": 9}], results_dir=tmp_path)
    assert kept == [{"run": "a", "x": 1}, {"run": "c", "x": 3}]
    kept[0]["x"] = 5  # a copy: the file's rows are not changed
    assert read_result(tmp_path / "k.json").rows[0]["x"] == 1
    (tmp_path / "k.json").write_text("{")
    with pytest.raises(ResultError, match="k.json"):
        earlier_rows("k", [], results_dir=tmp_path)


def test_write_is_atomic(tmp_path, monkeypatch):
    import sixdpose.fileio as fileio

    write_result("x", {"a": 1}, rows=[{"b": 2}], results_dir=tmp_path)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}

    def killed(*a, **k):
        raise OSError("killed")

    monkeypatch.setattr(fileio.os, "replace", killed)
    with pytest.raises(OSError):
        write_result("x", {"a": 2}, rows=[{"b": 3}], results_dir=tmp_path)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before  # old files, no temporary left


def _one_line(e: pytest.ExceptionInfo) -> str:
    msg = str(e.value)
    assert "\n" not in msg
    return msg


def test_bad_result_files_are_one_line_errors_naming_the_file(tmp_path):
    with pytest.raises(ResultError, match=r"nope\.json: no such result file") as e:
        read_result("nope", tmp_path)
    _one_line(e)
    (tmp_path / "bad.json").write_text('{"format": "sixdpose-result", "version": 1,')
    with pytest.raises(ResultError, match=r"bad\.json: corrupt result file \(invalid JSON") as e:
        read_result("bad", tmp_path)
    _one_line(e)
    (tmp_path / "other.json").write_text('{"a": 1}')
    with pytest.raises(ResultError, match=r"other\.json: not a sixdpose result file"):
        read_result("other", tmp_path)
    (tmp_path / "noprov.json").write_text('{"format": "sixdpose-result", "version": 1, "provenance": {"date": "x"}}')
    with pytest.raises(
        ResultError, match=r"noprov\.json: corrupt result file \(provenance lacks commit, dirty, hardware, command\)"
    ):
        read_result("noprov", tmp_path)
    (tmp_path / "future.json").write_text('{"format": "sixdpose-result", "version": 99}')
    with pytest.raises(ResultError, match=r"future\.json: result format version 99"):
        read_result("future", tmp_path)
    (tmp_path / "rows.json").write_text(
        json.dumps(
            {
                "format": "sixdpose-result",
                "version": 1,
                "rows": [1, 2],
                "provenance": dict.fromkeys(["commit", "dirty", "date", "hardware", "command"]),
            }
        )
    )
    with pytest.raises(ResultError, match=r"rows\.json: corrupt result file \(figures"):
        read_result("rows", tmp_path)


def test_bad_values_are_refused_before_anything_is_written(tmp_path):
    with pytest.raises(ResultError, match="result name '../x y'"):
        write_result("../x y", {"a": 1}, results_dir=tmp_path)
    with pytest.raises(ResultError, match=r"figures\.model has type object"):
        write_result("x", {"model": object()}, results_dir=tmp_path)
    with pytest.raises(ResultError, match="every row must be a dict"):
        write_result("x", [1, 2], results_dir=tmp_path)
    with pytest.raises(ResultError, match="content must be a dict"):
        write_result("x", "93 %", results_dir=tmp_path)
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------------------------
# README blocks
# --------------------------------------------------------------------------------------------
README = """# Title

Some text.

<!-- results:bench -->
| stale | table |
<!-- /results:bench -->

More text, and an example that is not a block:

```
<!-- results:example -->
<!-- /results:example -->
```
"""


def test_readme_rewrite_and_check(tmp_path, capsys):
    res = tmp_path / "results"
    write_result("bench", [{"method": "ransac", "acc": 93.456}, {"method": "fgr", "acc": None}], units={"acc": "%"},
                 results_dir=res)
    readme = tmp_path / "README.md"
    readme.write_text(README)
    args = ["--readme", str(readme), "--results", str(res)]
    assert readme_main(args + ["--check"]) == 1
    assert "bench" in capsys.readouterr().err and readme.read_text() == README  # --check changes nothing
    assert readme_main(args) == 0
    text = readme.read_text()
    assert "| method | acc (%) |\n|---|---|\n| ransac | 93.46 |\n| fgr | – |" in text
    assert "`results/bench.json`" in text and text.startswith("# Title\n\nSome text.\n\n<!-- results:bench -->\n|")
    assert ".</sub>\n<!-- /results:bench -->\n\nMore text" in text and text.endswith(README.split("More text")[1])
    assert readme_main(args + ["--check"]) == 0
    assert readme_main(args) == 0 and readme.read_text() == text  # idempotent


def test_readme_errors_are_one_line(tmp_path, capsys):
    readme = tmp_path / "README.md"
    readme.write_text("x\n<!-- results:bench -->\nold\n")
    assert readme_main(["--readme", str(readme), "--results", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "README.md:2" in err[0] and "no closing" in err[0]
    readme.write_text(README)
    assert readme_main(["--readme", str(readme), "--results", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bench.json: no such result file" in err[0]
    assert readme.read_text() == README


def _eval_result(res_dir, name, acc, ips=4.5):
    write_result(name, {"accuracy": acc, "n_gt": 1464, "n_correct": round(acc * 14.64), "instances_per_s": ips,
                        "mean_object_accuracy": acc - 1, "fps": 0.6, "n_images": 200, "n_estimates": 1464},
                 rows=[{"obj_id": 1, "name": "055_baseball", "n_gt": 80, "add_s_accuracy": acc},
                       {"obj_id": "all", "name": "mean over instances", "n_gt": 1464, "add_s_accuracy": acc}],
                 results_dir=res_dir, command=["sixdpose", "evaluate"])


def test_curated_block_has_the_papers_column(tmp_path):
    for name, acc in [("test_gt_ransac_icp", 92.14), ("test_kinect_gt_ransac_icp", 74.8),
                      ("test_gt_super4pcs_icp", 92.49), ("test_kinect_gt_super4pcs_icp", 84.08)]:
        _eval_result(tmp_path / "cpu", name, acc)
    md = render_block("depth_noise", tmp_path)
    lines = md.splitlines()
    assert "paper Table III" in lines[0]
    assert lines[2].startswith("| RANSAC + ICP | 53.55 | 92.14 | 74.80 | 1464 |")
    assert lines[3].startswith("| Super4PCS + ICP |  | 92.49 | 84.08 |")  # the paper has no Super4PCS + ICP row
    assert "`results/cpu/test_gt_ransac_icp.json`" in md and "commit" in md
    assert set(BLOCKS) >= {"learned_cpu_summary", "learned_cpu_per_object", "depth_noise", "ycbv_bop"}


# --------------------------------------------------------------------------------------------
# the commands that write results
# --------------------------------------------------------------------------------------------
def test_evaluate_writes_a_result(tmp_path, capsys):
    from sixdpose.artifacts.poses import PoseEstimate, write_results
    from sixdpose.cli import main
    from sixdpose.datasets import open_dataset
    from test_reg_helpers import write_synthetic_dataset

    syn = write_synthetic_dataset(tmp_path / "syn", n_images=2)
    ds = open_dataset(syn)
    rows = [
        PoseEstimate(s.scene_id, s.im_id, i.obj_id, 1.0, i.R, i.t, 0.25) for s in (ds[0], ds[1]) for i in s.instances
    ]
    write_results(rows, tmp_path / "r.csv")
    base = ["evaluate", "--data", str(syn), "--results", str(tmp_path / "r.csv"), "--min-px", "0", "--no-bop",
            "--out", str(tmp_path / "ev"), "--results-dir", str(tmp_path / "results")]
    assert main(base + ["--result-name", "bad name"]) == 2
    assert "bad name" in capsys.readouterr().err and not (tmp_path / "ev").exists()
    assert main(base + ["--result-name", "eval_gt"]) == 0
    r = read_result("eval_gt", tmp_path / "results")
    assert r.figures["accuracy"] == 100.0 and r.figures["n_gt"] == 3 and r.figures["fps"] == pytest.approx(4.0)
    assert r.row(obj_id="all")["add_s_accuracy"] == 100.0 and r.row(obj_id=15)["n_gt"] == 3
    assert r.units["accuracy"] == "%" and r.config["min_px"] == 0 and r.config["bop"] is False
    assert r.inputs[0]["path"].endswith("r.csv") and len(r.inputs[0]["sha256"]) == 64
    assert r.provenance["command"] == ["sixdpose", *base, "--result-name", "eval_gt"]


def test_a_benchmark_writes_its_figures(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("bench_sensors", REPO / "benchmarks" / "sensors.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(["--views", "1", "--width", "64", "--height", "48", "--results-dir", str(tmp_path)])
    out = capsys.readouterr().out
    assert "kinect" in out and f"result -> {tmp_path / 'sensors.json'}" in out
    r = read_result("sensors", tmp_path)
    assert [x["sensor"] for x in r.rows][:2] == ["ideal", "kinect"] and r.units["mean_ms"] == "ms per view"
    assert r.config["views"] == 1 and r.provenance["command"][:3] == ["python", "benchmarks/sensors.py", "--views"]
    mod.main(["--views", "1", "--width", "64", "--height", "48", "--results-dir", str(tmp_path / "n"), "--no-result"])
    assert not (tmp_path / "n").exists()
