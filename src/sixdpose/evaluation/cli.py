"""``sixdpose evaluate``: ADD(-S) accuracy, BOP 2019 average recalls, ADD-S AUC and timing of a results CSV;
``sixdpose merge-results``: per instance, the best-scored row of several results CSVs."""

from __future__ import annotations

import sys
from pathlib import Path

from .. import options as O
from ..constants import ADD_THRESHOLD


def register(sub) -> None:
    """Add the ``evaluate`` and ``merge-results`` subcommands."""
    _register_merge(sub)
    p = sub.add_parser("evaluate", help="ADD(-S), BOP average recall, ADD-S AUC and FPS of a BOP results CSV",
                       description="Score a results CSV against the dataset's ground truth (paper section V-A).")
    O.add(p, "--data")
    p.add_argument("--results", required=True, help="BOP results CSV (from `sixdpose register`)")
    O.add(p, "--split")
    O.add(p, "--out")
    O.add(p, "--min-px")
    p.add_argument("--threshold", type=O.Float(0.0, 10.0, lo_open=True), default=ADD_THRESHOLD,
                   help="correct if ADD(-S) < threshold x diameter")
    p.add_argument("--symmetric-ids", default=None,
                   help="BOP only: comma-separated obj_ids to treat as symmetric (overrides models_info.json)")
    p.add_argument("--all-images", action="store_true",
                   help="evaluate every image of the split (default: the images in the results); use it with "
                        "predicted masks, where images without detections have no rows")
    O.add(p, "--limit", help="evaluate the first N images of the split, with or without rows (as register / "
                             "predict-pose --limit N ran them; 0: all)")
    p.add_argument("--scenes", default=None,
                   help="comma-separated scene ids: evaluate every image of these scenes only (rows of other scenes "
                        "are ignored), e.g. one scene of a real sample for leave-one-scene-out figures")
    p.add_argument("--label", default=None, help="method label for the tables (default: results file stem)")
    O.add(p, "--no-progress")
    p.add_argument("--no-bop", action="store_true",
                   help="skip the BOP 2019 scores (AR_VSD, AR_MSSD, AR_MSPD, AR) and the ADD-S AUC")
    g = p.add_argument_group("result artifact")
    O.add(p, "--result-name", group=g,
          help="also write the summary and the per-object table, with commit, date, hardware and this command line, "
               "as the result artifact RESULTS_DIR/NAME.json (+ .csv); README tables are generated from these "
               "(python -m sixdpose.reporting.readme)")
    O.add(p, "--results-dir", group=g)
    p.set_defaults(func=_run)


def _run(args) -> int:
    from ..artifacts.poses import read_results
    from ..datasets.readers import open_dataset
    from ..fileio import claim_output_dir
    from .evaluate import evaluate, write_tables

    res_path = Path(args.results)
    out = Path(args.out) if args.out else res_path.with_name(res_path.stem + "_eval")
    claim_output_dir(out, "evaluate", create=False)  # refuse a foreign directory before any work
    if args.result_name is not None:
        from ..artifacts.results import result_path
        from ..fileio import check_output_location

        # a bad name, or a results dir that is a file or not writable, fails before any work
        check_output_location(result_path(args.result_name, args.results_dir), directory=False)
    ests = read_results(res_path)
    kw = {}
    if args.symmetric_ids:
        from ..errors import UserError

        try:
            kw["symmetric_ids"] = [int(x) for x in args.symmetric_ids.split(",") if x.strip()]
        except ValueError:
            raise UserError(f"--symmetric-ids: expected comma-separated integers, got {args.symmetric_ids!r}") from None
    ds = open_dataset(args.data, split=args.split, **kw)
    images = ds.keys()[: args.limit] if args.limit else (ds.keys() if args.all_images else None)
    if args.scenes is not None:
        images = _scene_images(args.scenes, images if images is not None else ds.keys(), ds.location)
        ests = [e for e in ests if (int(e.scene_id), int(e.im_id)) in set(images)]
    res = evaluate(ds, ests, min_px=args.min_px, threshold=args.threshold, progress=not args.no_progress, images=images,
                   bop=not args.no_bop)
    claim_output_dir(out, "evaluate")
    write_tables(res, out, label=args.label or res_path.stem)
    if args.result_name is not None:
        _write_result(args, res, res_path)
    print(f"ADD(-S) accuracy {res.accuracy:.2f}% ({res.n_correct}/{res.n_gt} GT instances; mean over objects "
          f"{res.mean_object_accuracy:.2f}%), {res.fps:.3f} FPS, {res.instances_per_s:.3f} instances/s -> {out}")
    if res.n_rejected or res.n_duplicates:
        r0 = res.rejected[0] if res.rejected else None
        first = f" (first: scene {r0[0]} image {r0[1]} obj {r0[2]}: {r0[3]})" if r0 else ""
        print(f"not scored: {res.n_rejected} rejected row(s){first}; {res.n_duplicates} repeated pose(s) counted once")
    if res.bop:
        b = res.bop
        print(
            f"BOP: AR {b['ar']:.2f} (VSD {b['ar_vsd']:.2f}, MSSD {b['ar_mssd']:.2f}, MSPD {b['ar_mspd']:.2f}); "
            f"ADD-S AUC {b['adds_auc']:.2f}"
            + (
                f"; symmetric without annotation (identity only in MSSD/MSPD): {b['unannotated_symmetric_ids']}"
                if b["unannotated_symmetric_ids"]
                else ""
            )
        )
    for oid, v in res.per_object.items():
        extra = f"  AR {v['bop']['ar']:6.2f}  ADD-S AUC {v['bop']['adds_auc']:6.2f}" if "bop" in v else ""
        print(f"  {oid:>3} {v['name']:<28} {v['n_correct']:>4}/{v['n_gt']:<4} {v['accuracy']:6.2f}%{extra}")
    return 0


def _scene_images(text: str, keys, location) -> list:
    """The keys of ``keys`` whose scene id is in the comma-separated ``text`` (UserError on a bad list or a
    scene the dataset lacks)."""
    from ..errors import UserError

    try:
        scenes = {int(x) for x in text.split(",") if x.strip()}
    except ValueError:
        raise UserError(f"--scenes: expected comma-separated integers, got {text!r}") from None
    have = {int(k[0]) for k in keys}
    if not scenes or scenes - have:
        raise UserError(f"--scenes: scene(s) {sorted(scenes - have) or text!r} not in {location} "
                        f"(it has {sorted(have)})")
    return [k for k in keys if int(k[0]) in scenes]


def _write_result(args, res, res_path: Path) -> None:
    """The evaluation as a result artifact: summary figures, per-object rows, the evaluation options and
    the configuration of the command that wrote the results CSV (``<results>.config.yml``, if present)."""
    from ..artifacts.poses import read_results_config, results_config_path
    from ..artifacts.results import file_input, write_result
    from .evaluate import UNITS, table_rows

    producer = results_config_path(res_path)
    inputs = [file_input(res_path)]
    producer_cfg = None
    if producer.is_file():
        inputs.append(file_input(producer))
        producer_cfg = read_results_config(res_path)
    label = args.label or res_path.stem
    path = write_result(
        args.result_name, dict(res.summary(), label=label), rows=table_rows(res), units=UNITS,
        description=f"sixdpose evaluate: ADD(-S) < {args.threshold:g} x diameter of {res_path.name} on {args.data} "
                    f"(GT instances with >= {args.min_px} visible px){'; BOP 2019 scores' if res.bop else ''}",
        results_dir=args.results_dir, command=getattr(args, "command_line", None),
        config={"data": str(args.data), "results": str(res_path), "split": args.split, "min_px": args.min_px,
                "threshold": args.threshold, "symmetric_ids": args.symmetric_ids, "all_images": args.all_images,
                "scenes": args.scenes,
                "limit": args.limit,
                "bop": not args.no_bop, "results_config": producer_cfg},
        inputs=inputs,
        notes="fps, instances_per_s and total_time come from the results CSV's per-image times (disk reads excluded), "
              "measured by the command that wrote it (register / predict-pose), not by evaluate; provenance is "
              "that of the evaluation, inputs identify the results CSV by its sha256.")
    print(f"result -> {path}")


def _register_merge(sub) -> None:
    p = sub.add_parser("merge-results", help="per instance, the best-scored row of several results CSVs",
                       description="Pose-source fusion: keep, for every instance, the row with the highest score "
                                   "among results CSVs of the same frames and masks (e.g. `register --verify` and "
                                   "`predict-pose --icp --verify`, whose scores are the same verification's); the "
                                   "merged row's time is the sum of the sources' times of its image.")
    p.add_argument("--results", required=True, action="append",
                   help="a results CSV (give two or more: --results A.csv --results B.csv)")
    O.add(p, "--out", help="merged results CSV to write")
    p.set_defaults(func=_run_merge)


def _run_merge(args) -> int:
    from ..artifacts.poses import RESULTS_HEADER, merge_by_score, read_results, write_results
    from ..errors import UserError
    from ..fileio import claim_output_file

    if len(args.results) < 2:
        raise UserError(f"--results: give two or more results CSVs, got {len(args.results)}")
    out = Path(args.out)
    claim_output_file(out, RESULTS_HEADER)  # refuse a foreign file before any work
    tables = [read_results(r) for r in args.results]
    rows, chosen = merge_by_score(tables, names=args.results)
    for line in _verification_mismatch(args.results):
        print(f"sixdpose merge-results: warning: {line}", file=sys.stderr, flush=True)
    write_results(rows, out)
    print(f"wrote {len(rows)} rows to {out}; taken from " + ", ".join(
        f"{name}: {n}" for name, n in zip(args.results, chosen, strict=True)))
    return 0


def _verification_mismatch(paths) -> list[str]:
    """Warnings when the results CSVs' scores are not the same verification's (a source not verified, or
    verified with other ``verify_*`` settings): merging by score then compares unlike scores."""
    from ..artifacts.poses import read_results_config, results_verification

    found = [(p, results_verification(read_results_config(p))) for p in paths]
    out = [f"{p}: not made with the hypothesis verification (--verify): its scores are not comparable"
           for p, v in found if v == {}]
    ref = next(((p, v) for p, v in found if v), None)
    for p, v in found:
        if ref is not None and v and v != ref[1]:
            k = sorted(key for key in set(v) | set(ref[1]) if v.get(key) != ref[1].get(key))[0]
            out.append(f"{p}: verified with {k}={v.get(k)!r}, {ref[0]} with {ref[1].get(k)!r}: the scores differ in "
                       "meaning")
    return out
