"""Hypothesis verification (``register --verify``) on the YCB-Video sample, on and off, per scene and object.

Reads the evaluations of the results CSVs made by (for M in super4pcs, ransac, fgr; with and without
``--verify``; RANSAC also with the ``fast`` preset, verified; ``runs/verify/<stem>.csv``)::

    sixdpose register --data ../shared/data/ycbv_sample --split train_real --method M --icp --masks gt \\
        --profile default|fast --workers 1 --verify|--no-verify --out runs/verify/<stem>.csv
    sixdpose evaluate --data ../shared/data/ycbv_sample --split train_real --symmetric-ids \\
        1,13,14,16,18,19,20,21 --min-px 0 --no-bop --results <csv> --out runs/verify/<stem>_eval_<all|0|1>

and, with ``--pose RUN`` (a dense pose run trained on generated data only), the cascade of the learned pose
and the hybrid method (:data:`CASCADES`: the network's pose, ICP, verification; RANSAC of the ``fast`` preset,
or Super4PCS, verified, for the instances whose verified score is below ``verify_retry_below``, 0.6), pinned to
one core::

    taskset -c 0 sixdpose predict-pose --pose RUN --data ../shared/data/ycbv_sample --split train_real \
        --masks gt --icp --verify --fallback ransac|super4pcs --threads 1 --set ransac_threshold=0.06 --out <csv>

(the ``_0`` / ``_1`` evaluations on the CSV's rows of scene 000000 / 000001) and writes the result
artifacts ``results/verify_ycbv_sample.json`` (one row per method and switch) and
``results/verify_ycbv_sample_per_object.json`` (one row per scene and object). ``--figure PNG`` also draws
accuracy against instances per second per core (one register process: per core) from the first artifact
(``--figure-only``: from the committed artifact, without the runs).

    python benchmarks/verify_ycbv_sample.py [--run] [--pose RUN [--repeat N]] [--runs runs/verify] \
        [--figure figures/verify_ycbv_sample.png]

``--run`` first runs those commands (a results CSV already there is kept: delete it to measure again), so
on an otherwise idle machine the speed column is one core's. ``inst_per_s`` counts the per-image times,
which leave out disk reads and the objects' onboarding (their model-side data built on first use, about a
second per object and preset, once per process: BOP 2023 times onboarding apart); ``onboarding_s`` is that
total (from the CSV's ``.config.yml``) and ``inst_per_s_with_onboarding`` charges it to these 140 instances.
``--keep`` keeps the rows (and per-object columns) of the artifacts already there whose runs are not in
``--runs`` this time (the cascades of a pose run that is not on this machine), each row saying when it was
measured (``measured``: the date, commit and CPU of the run that measured it) so rows of different code or
machines are not mistaken for one run. ``--repeat N`` runs each cascade N more times (same estimates) and
adds the spread of both speeds over the runs (``*_median``, ``*_runs``: min-max); on a shared virtual
machine one run's speed varies by tens of percent, so the figure plots the median where there is one.
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from sixdpose.artifacts.poses import read_results_config
from sixdpose.artifacts.results import write_result

#: ``measured`` of the rows measured by the run that writes the artifact (``--keep``)
HERE = "this artifact (its provenance)"
#: (method label, register --method, verify, results CSV stem under --runs, register --profile)
RUNS = [
    ("Super4PCS + ICP", "super4pcs", False, "base_s4pcs_icp", "default"),
    ("Super4PCS + ICP", "super4pcs", True, "final_super4pcs_icp_verify", "default"),
    ("RANSAC + ICP", "ransac", False, "final_ransac_icp", "default"),
    ("RANSAC + ICP", "ransac", True, "final_ransac_icp_verify", "default"),
    ("RANSAC + ICP (fast)", "ransac", True, "fast_ransac_icp_verify", "fast"),
    ("FGR + ICP", "fgr", False, "final_fgr_icp", "default"),
    ("FGR + ICP", "fgr", True, "final_fgr_icp_verify", "default"),
]

#: the cascade rows (``--pose``): (method label, results CSV stem, predict-pose switches); the pose run's
#: directory name is added to the label
CASCADES = [
    ("learned + ICP, RANSAC (fast) below 0.6", "cascade_learned_icp_verify_ransac",
     ["--icp", "--verify", "--fallback", "ransac", "--threads", "1", "--set", "ransac_threshold=0.06"]),
    ("learned + ICP, Super4PCS below 0.6", "cascade_learned_icp_verify_super4pcs",
     ["--icp", "--verify", "--fallback", "super4pcs", "--threads", "1", "--set", "ransac_threshold=0.06"]),
]


#: the sample, its split and the BOP symmetric ids of YCB-Video (the sample carries no annotation)
DATA, SPLIT, SYMMETRIC = "../shared/data/ycbv_sample", "train_real", "1,13,14,16,18,19,20,21"


def run_all(runs: Path, data: str, pose: str | None = None, repeat: int = 0) -> None:
    """Run ``register`` (one process) and the three evaluations of every entry of :data:`RUNS` whose results
    CSV is not in ``runs`` yet; with ``pose`` (a pose run directory) also :data:`CASCADES`' ``predict-pose``,
    pinned to one core (``taskset -c 0``, Linux), and ``repeat`` more times each (``<stem>_rep<k>.csv``,
    timing only: the estimates are the same)."""
    exe = [sys.executable, "-m", "sixdpose"]
    runs.mkdir(parents=True, exist_ok=True)
    todo = [(stem, ["register", "--method", method, "--icp", "--profile", profile, "--min-px", "0", "--workers", "1",
                    "--verify" if on else "--no-verify"]) for _, method, on, stem, profile in RUNS]
    if pose:
        todo += [(stem, ["predict-pose", "--pose", pose, *switches]) for _, stem, switches in CASCADES]
    for k in range(1, repeat + 1 if pose else 1):
        todo += [(f"{stem}_rep{k}", ["predict-pose", "--pose", pose, *switches]) for _, stem, switches in CASCADES]
    for stem, cmd in todo:
        csv_path = runs / f"{stem}.csv"
        if not csv_path.is_file():
            pin = ["taskset", "-c", "0"] if cmd[0] == "predict-pose" else []
            subprocess.run([*pin, *exe, cmd[0], "--data", data, "--split", SPLIT, "--masks", "gt", "--no-progress",
                            *cmd[1:], "--out", str(csv_path)], check=True)
        if "_rep" in stem:  # a repeat is only timed
            continue
        for part in ("all", "0", "1"):
            subprocess.run([*exe, "evaluate", "--data", data, "--split", SPLIT, "--symmetric-ids", SYMMETRIC,
                            "--min-px", "0", "--no-bop", "--no-progress", "--results", str(csv_path),
                            "--out", str(runs / f"{stem}_eval_{part}"),
                            *([] if part == "all" else ["--scenes", part])], check=True, stdout=subprocess.DEVNULL)
        print(f"{stem}: done", flush=True)


def main() -> None:
    """Collect the evaluations and write the two result artifacts."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--run", action="store_true", help="first run register and evaluate (missing CSVs only)")
    ap.add_argument("--data", default=DATA, help="the BOP YCB-Video sample")
    ap.add_argument("--runs", default="runs/verify")
    ap.add_argument("--pose", default=None, help="a dense pose run: also the cascade row (learned, RANSAC fallback)")
    ap.add_argument("--repeat", type=int, default=0,
                    help="with --run --pose: run each cascade this many more times (its speed's spread)")
    ap.add_argument("--results-dir", default="results")
    ap.add_argument("--figure", default=None, help="also draw accuracy against speed into this PNG")
    ap.add_argument("--figure-only", action="store_true", help="only draw --figure from the existing artifact")
    ap.add_argument("--keep", action="store_true",
                    help="keep the earlier artifact's rows whose runs are not here (marked when measured)")
    ap.add_argument("--note", default="one register process (--workers 1) on the 2-core CPU",
                    help="how the runs were made (the artifact's notes)")
    a = ap.parse_args()
    if a.figure_only:
        if not a.figure:
            ap.error("--figure-only needs --figure")
        draw(Path(a.results_dir) / "verify_ycbv_sample.json", a.figure)
        return
    runs = Path(a.runs)
    if a.run:
        run_all(runs, a.data, a.pose, a.repeat)
    old_rows, old_per_obj, old_when = _earlier(Path(a.results_dir)) if a.keep else ([], [], "")
    rows, per_obj, inputs = [], {}, []
    entries = [(label, on, stem) for label, _, on, stem, _ in RUNS]
    for label, stem, _ in CASCADES:
        cascade = runs / f"{stem}.csv"
        if cascade.is_file():  # the pose run is named in the CSV's config
            run_path = Path(str((read_results_config(cascade) or {}).get("pose_run") or "?"))
            run = (run_path.parent if run_path.suffix == ".pt" else run_path).name
            entries.append((f"{label} ({run})", True, stem))
    for label, on, stem in entries:
        row = {"method": label, "verify": "on" if on else "off"}
        for part, col in (("0", "scene 000000"), ("1", "scene 000001"), ("all", "both scenes")):
            ev = runs / f"{stem}_eval_{part}"
            s = json.loads((ev / "summary.json").read_text())
            row[col] = f"{s['n_correct']}/{s['n_gt']} ({s['accuracy']:.2f} %)"
            if part == "all":
                row["accuracy"] = round(s["accuracy"], 2)
                row["inst_per_s"] = round(s["instances_per_s"], 2)
                # the objects' onboarding (first-use model-side data), which the per-image times leave out
                onb = (read_results_config(runs / f"{stem}.csv") or {}).get("onboarding_s")
                if onb is not None:
                    row["onboarding_s"] = round(float(onb), 1)
                    row["inst_per_s_with_onboarding"] = round(_speed(runs / f"{stem}.csv")[1], 2)
            else:
                with open(ev / "add_s_per_object.csv") as fh:
                    for r in csv.DictReader(fh):
                        if not r["obj_id"].isdigit():
                            continue
                        key = (int(part), int(r["obj_id"]))
                        d = per_obj.setdefault(key, {"scene": f"00000{part}", "obj_id": int(r["obj_id"]),
                                                     "object": r.get("name", "")})
                        d[f"{label} {'on' if on else 'off'}"] = f"{r['n_correct']}/{r['n_gt']}"
        reps = [runs / f"{stem}.csv", *sorted(runs.glob(f"{stem}_rep*.csv"))]
        if len(reps) > 1:  # the cascade's speed over its runs: the median, and min-max
            per_image, charged = zip(*(_speed(r) for r in reps), strict=True)
            row["inst_per_s_median"] = round(float(np.median(per_image)), 2)
            row["inst_per_s_runs"] = _spread(per_image)
            row["inst_per_s_with_onboarding_median"] = round(float(np.median(charged)), 2)
            row["inst_per_s_with_onboarding_runs"] = _spread(charged)
        if a.keep:
            row["measured"] = HERE
        rows.append(row)
        inputs.append(str(runs / f"{stem}.csv"))
    if a.keep:
        here = {(r["method"], r["verify"]) for r in rows}
        kept = [r for r in old_rows if (r["method"], r["verify"]) not in here]
        for r in kept:  # rows measured by the earlier artifact's own run take its provenance
            if r.get("measured", HERE) == HERE:
                r["measured"] = old_when
        rows += kept
        cols = {f"{r['method']} {r['verify']}" for r in kept}
        for r in old_per_obj:
            key = (int(r["scene"]), int(r["obj_id"]))
            d = per_obj.setdefault(key, {k: r[k] for k in ("scene", "obj_id", "object")})
            d.update({k: v for k, v in r.items() if k in cols})
    write_result("verify_ycbv_sample", rows, units={"inst_per_s": "instances/s", "accuracy": "%", "onboarding_s": "s",
                                                    "inst_per_s_with_onboarding": "instances/s",
                                                    "inst_per_s_median": "instances/s",
                                                    "inst_per_s_with_onboarding_median": "instances/s"},
                 results_dir=a.results_dir, notes=a.note,
                 description="register --icp [--verify] on ycbv_sample train_real, GT masks, min-px 0, BOP "
                             "symmetric ids 1,13,14,16,18-21: correct/GT per scene", inputs=inputs)
    write_result("verify_ycbv_sample_per_object", [per_obj[k] for k in sorted(per_obj)],
                 results_dir=a.results_dir, inputs=inputs,
                 description="register --icp [--verify] on ycbv_sample train_real: correct/GT per scene and object")
    if a.figure:
        draw(Path(a.results_dir) / "verify_ycbv_sample.json", a.figure)


def _earlier(results_dir: Path) -> tuple[list, list, str]:
    """The rows of the two artifacts already in ``results_dir`` and when they were measured (the date, commit
    and CPU of their provenance: speeds of two machines are not to be compared); empty when there are none."""
    from sixdpose.artifacts.results import read_result

    try:
        main, per = read_result(results_dir / "verify_ycbv_sample.json"), \
            read_result(results_dir / "verify_ycbv_sample_per_object.json")
    except (OSError, ValueError):
        return [], [], ""
    prov = main.provenance or {}
    cpu = (prov.get("hardware") or {}).get("cpu", "?")
    when = f"{str(prov.get('date', '?'))[:10]} ({str(prov.get('commit', '?'))[:7]}, {cpu})"
    return [dict(r) for r in main.rows], [dict(r) for r in per.rows], when


def _speed(csv_path: Path) -> tuple[float, float]:
    """Instances per second of a results CSV from its per-image times, without and with the objects'
    onboarding (``onboarding_s`` of its ``.config.yml``)."""
    with open(csv_path) as fh:
        rows = list(csv.DictReader(fh))
    total = sum(float(r["time"]) for r in {(r["scene_id"], r["im_id"]): r for r in rows}.values())
    onb = float((read_results_config(csv_path) or {}).get("onboarding_s") or 0.0)
    return len(rows) / total, len(rows) / (total + onb)


def _spread(values) -> str:
    """``"min-max (n runs)"`` of instances per second."""
    return f"{min(values):.2f}-{max(values):.2f} ({len(values)} runs)"


def draw(result: Path, png: str) -> None:
    """Draw :func:`sixdpose.reporting.charts.plot_speed_accuracy` of the artifact ``result`` into ``png``."""
    from sixdpose.artifacts.results import read_result
    from sixdpose.reporting.charts import plot_speed_accuracy, save

    rows = [r if r.get("measured", HERE) == HERE else {**r, "method": f"{r['method']} [{r['measured']}]"}
            for r in read_result(result).rows]  # rows kept from an earlier run say so in the legend
    fig = plot_speed_accuracy(rows,
                              title="register --icp [--verify] on the YCB-Video sample (GT masks, 140 instances)")
    if fig is None:
        raise SystemExit(f"{result}: no row with both an accuracy and inst_per_s")
    print(save(fig, png))


if __name__ == "__main__":
    main()
