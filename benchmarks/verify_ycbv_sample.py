"""Hypothesis verification (``register --verify``) on the YCB-Video sample, on and off, per scene and object.

Reads the evaluations of the results CSVs made by (for M in super4pcs, ransac, fgr; with and without
``--verify``; ``runs/verify/<stem>.csv``)::

    sixdpose register --data ../shared/data/ycbv_sample --split train_real --method M --icp --masks gt \\
        --workers 1 [--verify] --out runs/verify/<stem>.csv
    sixdpose evaluate --data ../shared/data/ycbv_sample --split train_real --symmetric-ids \\
        1,13,14,16,18,19,20,21 --min-px 0 --no-bop --results <csv> --out runs/verify/<stem>_eval_<all|0|1>

(the ``_0`` / ``_1`` evaluations on the CSV's rows of scene 000000 / 000001) and writes the result
artifacts ``results/verify_ycbv_sample.json`` (one row per method and switch) and
``results/verify_ycbv_sample_per_object.json`` (one row per scene and object).

    python benchmarks/verify_ycbv_sample.py [--runs runs/verify]
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

from sixdpose.artifacts.results import write_result

#: (method label, verify, results CSV stem under --runs)
RUNS = [
    ("Super4PCS + ICP", False, "base_s4pcs_icp"),
    ("Super4PCS + ICP", True, "final_super4pcs_icp_verify"),
    ("RANSAC + ICP", False, "final_ransac_icp"),
    ("RANSAC + ICP", True, "final_ransac_icp_verify"),
    ("FGR + ICP", False, "final_fgr_icp"),
    ("FGR + ICP", True, "final_fgr_icp_verify"),
]


def main() -> None:
    """Collect the evaluations and write the two result artifacts."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", default="runs/verify")
    ap.add_argument("--results-dir", default="results")
    a = ap.parse_args()
    runs = Path(a.runs)
    rows, per_obj, inputs = [], {}, []
    for label, on, stem in RUNS:
        row = {"method": label, "verify": "on" if on else "off"}
        for part, col in (("0", "scene 000000"), ("1", "scene 000001"), ("all", "both scenes")):
            ev = runs / f"{stem}_eval_{part}"
            s = json.loads((ev / "summary.json").read_text())
            row[col] = f"{s['n_correct']}/{s['n_gt']} ({s['accuracy']:.2f} %)"
            if part == "all":
                row["inst_per_s"] = round(s["instances_per_s"], 2)
            else:
                with open(ev / "add_s_per_object.csv") as fh:
                    for r in csv.DictReader(fh):
                        if not r["obj_id"].isdigit():
                            continue
                        key = (int(part), int(r["obj_id"]))
                        d = per_obj.setdefault(key, {"scene": f"00000{part}", "obj_id": int(r["obj_id"]),
                                                     "object": r.get("name", "")})
                        d[f"{label} {'on' if on else 'off'}"] = f"{r['n_correct']}/{r['n_gt']}"
        rows.append(row)
        inputs.append(str(runs / f"{stem}.csv"))
    note = ("one register process under nice -n 15 on the 2-core CPU shared with a training job; the load "
            "changed between runs (the Super4PCS off run had the heaviest)")
    write_result("verify_ycbv_sample", rows, units={"inst_per_s": "instances/s"}, results_dir=a.results_dir,
                 description="register --icp [--verify] on ycbv_sample train_real, GT masks, min-px 0, BOP "
                             "symmetric ids 1,13,14,16,18-21: correct/GT per scene", inputs=inputs, notes=note)
    write_result("verify_ycbv_sample_per_object", [per_obj[k] for k in sorted(per_obj)],
                 results_dir=a.results_dir, inputs=inputs,
                 description="register --icp [--verify] on ycbv_sample train_real: correct/GT per scene and object")


if __name__ == "__main__":
    main()
