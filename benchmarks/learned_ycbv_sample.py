"""A learned pose run on the real YCB-Video sample, leave-one-scene-out: alone, + ICP, + verification.

For each pose run given (``--pose LABEL=RUN_DIR``, repeatable) and each variant (alone, ``--icp``,
``--verify``, ``--icp --verify``, ``--icp --colour-verify --verify`` with the wider verification
settings of :data:`WIDE`, and the cascade ``--icp --verify --fallback ransac``: RANSAC of the ``fast``
preset, verified, for the instances whose verified learned pose scores below ``verify_retry_below``)
this runs, unless its CSV is already there (so an interrupted collection resumes)::

    sixdpose predict-pose --pose RUN --data ../shared/data/ycbv_sample --split train_real --masks gt \\
        [--icp] [--colour-verify] [--verify] [--set ...] --out <work>/<label>_<variant>.csv

and one more variant, pose-source fusion (:data:`MERGED`): the ``--icp --verify`` CSV and RANSAC + ICP +
verification's (``sixdpose register ... --method ransac --icp --verify --workers 1``, once per work
directory) merged per instance by their verification scores (``sixdpose merge-results``; its time per
image is the sum of both, so its instances/s is the two commands' together)
then scores the CSV on each scene of the sample alone and on both (``evaluate --scenes``; GT masks,
``--min-px 0``, BOP symmetric ids 1,13,14,16,18-21) and writes ``results/learned_ycbv_sample.json``:
one row per run and variant, ``correct/GT (accuracy)`` for scene 000000, scene 000001 and both, and the
instances estimated per second of ``predict-pose``'s own per-image time (one process, both cores: on an
otherwise idle machine, for the speed to mean anything). The
networks are trained only on generated data; scene 000000 is the sample's tuning scene and 000001 the
held-out one (leave-one-scene-out: choose on one column, report the other).

    python benchmarks/learned_ycbv_sample.py --pose dense=runs/pose_ycbv_dense [--work runs/learned_ycbv_sample]

``--set KEY=VALUE`` (repeatable) is passed to every ``predict-pose`` of the invocation (e.g. ``--set
ransac_threshold=0.06``, the dense fit's inlier distance) and recorded in the rows' ``predict-pose --set``
column; give such a run its own label.

``--keep`` keeps the rows of the result file already there whose run label is not given this time (runs
measured earlier, perhaps on another machine: each row names its pose run and the date it was measured),
so a new run can be added beside the old ones without their run directories.
"""

from __future__ import annotations

import argparse
import datetime
import json
import subprocess
import sys
from pathlib import Path

from sixdpose.artifacts.results import earlier_rows, write_result
from sixdpose.registration.presets import VAL_CHOSEN_VERIFY, as_set_args

#: the verification's wider settings, chosen on the synthetic val split (never on the sample): the model's
#: near-symmetries as hypotheses, the grey-detail texture term and the hypotheses recentred on the cloud
WIDE = as_set_args({**VAL_CHOSEN_VERIFY, "verify_recentre": True})
#: (variant label, file stem, predict-pose switches)
VARIANTS = [("alone", "alone", []), ("+ ICP", "icp", ["--icp"]), ("+ verify", "verify", ["--verify"]),
            ("+ ICP + verify", "icp_verify", ["--icp", "--verify"]),
            ("+ ICP + colour search + wide verify", "icp_colour_verify_wide",
             ["--icp", "--colour-verify", "--verify", *WIDE]),
            ("+ ICP + verify, RANSAC (fast) below 0.6", "icp_verify_fallback_ransac",
             ["--icp", "--verify", "--fallback", "ransac"])]
SYMMETRIC_IDS = "1,13,14,16,18,19,20,21"
#: the merged variant: the ``+ ICP + verify`` CSV and this hybrid method's (``register``, verified, one
#: process) merged per instance by their verification scores (``sixdpose merge-results``)
MERGED = ("+ ICP + verify, merged with RANSAC + ICP + verify", "icp_verify_merged_ransac", "icp_verify")
HYBRID = ["--method", "ransac", "--icp", "--verify", "--workers", "1"]


def _cli(*args: str) -> None:
    """Run one ``sixdpose`` command of this interpreter's environment; exits with its status on failure."""
    cmd = [str(Path(sys.executable).with_name("sixdpose")), *args]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode:
        sys.exit(f"learned_ycbv_sample: {' '.join(cmd)} failed ({proc.returncode}): "
                 f"{(proc.stderr.strip().splitlines() or ['?'])[-1]}")


def _instances_per_s(csv: Path) -> float:
    """Instances estimated per second of ``predict-pose``'s own time in the results CSV ``csv`` (the rows,
    over the sum of each image's ``time``, which excludes disk reads); 0.0 where no time was recorded."""
    from sixdpose.artifacts.poses import read_results

    rows = read_results(csv)
    seconds = sum({(r.scene_id, r.im_id): r.time for r in rows}.values())
    return round(len(rows) / seconds, 2) if seconds > 0 else 0.0


def main() -> None:
    """Predict, evaluate per scene and write ``results/learned_ycbv_sample.json``; prints the rows."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pose", action="append", required=True, help="LABEL=RUN_DIR of train-pose (repeatable)")
    ap.add_argument("--data", default="../shared/data/ycbv_sample")
    ap.add_argument("--work", default="runs/learned_ycbv_sample", help="results CSVs and evaluations")
    ap.add_argument("--results-dir", default="results")
    ap.add_argument("--keep", action="store_true", help="keep the existing result's rows of the runs not given")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a predict-pose --set of every run given (repeatable)")
    a = ap.parse_args()
    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    rows, inputs = [], []
    sets = [x for kv in a.set for x in ("--set", kv)]
    for spec in a.pose:
        label, _, run = spec.partition("=")
        if not run or not Path(run, "model.pt").is_file():
            sys.exit(f"learned_ycbv_sample: --pose {spec}: expected LABEL=RUN_DIR with a model.pt")
        for variant, suffix, switches in [*VARIANTS, (MERGED[0], MERGED[1], None)]:
            stem = f"{label}_{suffix}"
            out = work / f"{stem}.csv"
            if switches is None:  # the merged variant (the hybrid CSV is shared by every run)
                hybrid = work / "hybrid_ransac_icp_verify.csv"
                if not hybrid.is_file():
                    _cli("register", "--data", a.data, "--split", "train_real", "--masks", "gt", "--min-px", "0",
                         "--no-progress", *HYBRID, "--out", str(hybrid))
                _cli("merge-results", "--results", str(work / f"{label}_{MERGED[2]}.csv"), "--results", str(hybrid),
                     "--out", str(out))
            elif not out.is_file():
                _cli("predict-pose", "--pose", run, "--data", a.data, "--split", "train_real", "--masks", "gt",
                     "--no-progress", "--out", str(out), *sets, *switches)
            row = {"run": label, "pose run": run, "variant": variant, "predict-pose --set": " ".join(a.set) or "-",
                   "measured": datetime.date.today().isoformat(), "instances/s": _instances_per_s(out)}
            for part, col in (("0", "scene 000000 (tuning)"), ("1", "scene 000001 (held out)"), ("all", "both")):
                ev = work / f"{stem}_eval_{part}"
                _cli("evaluate", "--data", a.data, "--split", "train_real", "--symmetric-ids", SYMMETRIC_IDS,
                     "--min-px", "0", "--all-images", "--no-bop", "--no-progress", "--results", str(out),
                     "--out", str(ev), *([] if part == "all" else ["--scenes", part]))
                s = json.loads((ev / "summary.json").read_text())
                row[col] = f"{s['n_correct']}/{s['n_gt']} ({s['accuracy']:.2f} %)"
            rows.append(row)
            inputs.append(str(out))
            print(row, flush=True)
    if a.keep:
        kept = earlier_rows("learned_ycbv_sample", rows, results_dir=a.results_dir)
        for r in kept:
            r.setdefault("measured", "an earlier session (its run is not here)")
            r.setdefault("predict-pose --set", "-")
        rows = rows + kept
    cols = ("run", "pose run", "variant", "predict-pose --set", "measured", "scene 000000 (tuning)",
            "scene 000001 (held out)", "both", "instances/s")
    rows = [{k: r.get(k) for k in cols} for r in rows]
    write_result("learned_ycbv_sample", rows, results_dir=a.results_dir, inputs=inputs,
                 description="predict-pose [--icp] [--verify] on ycbv_sample train_real (networks trained on generated "
                             "data only), GT masks, min-px 0, BOP symmetric ids 1,13,14,16,18-21: correct/GT per scene",
                 notes="scene 000000 is the tuning scene, 000001 the held-out one (leave-one-scene-out)")


if __name__ == "__main__":
    main()
