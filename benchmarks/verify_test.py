"""Hypothesis verification on the synthetic ``data/test`` split: Super4PCS and RANSAC (+ ICP + verify, the two
opt-in settings chosen on ``data/val``) and their per-instance fusion, per object.

The runs (``runs/verify_test/<stem>.csv``; ``--run`` makes the missing ones)::

    sixdpose register --data data/test --method super4pcs|ransac --icp --verify --masks gt --workers 2 \\
        --set verify_near_symmetries=6 --set verify_detail_share=0.5 --set verify_detail_rel=0.1 --out <csv>
    sixdpose merge-results --results <super4pcs csv> --results <ransac csv> --out <merged csv>
    sixdpose evaluate --data data/test --results <csv> --no-bop --out runs/verify_test/<stem>_eval

``merge-results`` keeps, per instance, the row with the higher verification score (no setting of its own);
its time is the sum of both sources' times. Writes the result artifact ``results/verify_test_gt_nsd.json``:
one row per object (correct / GT instances of each method, GT instances with >= 400 visible pixels, BOP
symmetric flags of ``objects.csv``), then the overall rows, with instances per second (two ``register``
workers on the 2-core CPU, so per core: the sum of the per-image times; the objects' onboarding apart,
``onboarding_s``).

    python benchmarks/verify_test.py [--run] [--data data/test] [--runs runs/verify_test] [--name NAME]

(``--data data/val --runs runs/verify_val --name verify_val_gt_nsd``: the same on the tuning split.)
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
from pathlib import Path

from sixdpose.artifacts.poses import read_results_config
from sixdpose.artifacts.results import write_result
from sixdpose.registration.presets import VAL_CHOSEN_VERIFY, as_set_args

#: the settings chosen on ``data/val`` (docs/registration.md, "Two opt-in extensions")
NSD = as_set_args(VAL_CHOSEN_VERIFY)
#: (column label, results CSV stem, register --method or None for the fusion of the two)
RUNS = [("Super4PCS + ICP + verify", "super4pcs_icp_verify_nsd", "super4pcs"),
        ("RANSAC + ICP + verify", "ransac_icp_verify_nsd", "ransac"),
        ("fusion of the two (merge-results)", "merged_nsd", None)]


def run_all(runs: Path, data: str) -> None:
    """Make every missing results CSV of :data:`RUNS` and its evaluation."""
    exe = [sys.executable, "-m", "sixdpose"]
    runs.mkdir(parents=True, exist_ok=True)
    for _, stem, method in RUNS:
        out = runs / f"{stem}.csv"
        if not out.is_file():
            if method:
                cmd = ["register", "--data", data, "--method", method, "--icp", "--verify", "--masks", "gt",
                       "--workers", "2", "--no-progress", *NSD, "--out", str(out)]
            else:
                cmd = ["merge-results", *[a for _, s, m in RUNS if m for a in ("--results", str(runs / f"{s}.csv"))],
                       "--out", str(out)]
            subprocess.run([*exe, *cmd], check=True)
        subprocess.run([*exe, "evaluate", "--data", data, "--results", str(out), "--no-bop", "--no-progress",
                        "--out", str(runs / f"{stem}_eval")], check=True, stdout=subprocess.DEVNULL)
        print(f"{stem}: done", flush=True)


def main() -> None:
    """Collect the evaluations into the result artifact."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--run", action="store_true", help="first make the missing runs and evaluations")
    ap.add_argument("--data", default="data/test")
    ap.add_argument("--runs", default="runs/verify_test")
    ap.add_argument("--results-dir", default="results")
    ap.add_argument("--name", default="verify_test_gt_nsd", help="the result artifact's name (another split's)")
    ap.add_argument("--note", default="", help="added to the artifact's notes (how the runs were made)")
    a = ap.parse_args()
    runs = Path(a.runs)
    if a.run:
        run_all(runs, a.data)
    rows: dict[str, dict] = {}
    inputs = []
    for label, stem, method in RUNS:
        ev = runs / f"{stem}_eval"
        with open(ev / "add_s_per_object.csv") as fh:
            for r in csv.DictReader(fh):
                if not r["obj_id"].isdigit():
                    continue
                d = rows.setdefault(r["obj_id"], {"obj_id": int(r["obj_id"]), "object": r.get("name", "")})
                d[label] = f"{r['n_correct']}/{r['n_gt']}"
        s = json.loads((ev / "summary.json").read_text())
        total = rows.setdefault("all", {"obj_id": "all", "object": "all instances"})
        total[label] = f"{s['n_correct']}/{s['n_gt']} ({s['accuracy']:.2f} %)"
        speed = rows.setdefault("speed", {"obj_id": "speed", "object": "instances/s per core (per-image times)"})
        speed[label] = f"{s['instances_per_s']:.2f}"
        if method:
            onb = rows.setdefault("onboarding", {"obj_id": "onboarding", "object": "onboarding_s (s, apart)"})
            onb[label] = f"{float((read_results_config(runs / f'{stem}.csv') or {}).get('onboarding_s') or 0):.1f}"
        inputs.append(str(runs / f"{stem}.csv"))
    order = sorted((k for k in rows if k.isdigit()), key=int) + ["all", "speed", "onboarding"]
    write_result(a.name, [rows[k] for k in order if k in rows], results_dir=a.results_dir,
                 inputs=inputs, notes="register --workers 2 on the 2-core CPU; merge-results' time is the sum of "
                                      "both sources'" + (f"; {a.note}" if a.note else ""),
                 description=f"register --icp --verify (near-symmetries, grey detail) on {a.data}, GT masks, GT "
                             "instances with >= 400 visible px: correct/GT per object, and the fusion of the two")


if __name__ == "__main__":
    main()
