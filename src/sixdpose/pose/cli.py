"""Subcommands of the learned pose stage: ``train-pose``, ``train-refiner``, ``predict-pose``, ``pose-ablation``.

Multi-process training: ``torchrun --nproc_per_node N -m sixdpose.cli train-pose ...`` (gloo on CPU,
NCCL on GPUs; only rank 0 writes files).
"""

from __future__ import annotations

import os
from pathlib import Path

from .. import options as O
from ..config import add_set_option, parse_overrides
from ..logs import setup_logging
from ..registration import PRESETS
from ..registry import HYBRID_ALGORITHMS
from .config import PROFILES, REFINER_PROFILES, RefinerConfig


def _overrides(args) -> dict:
    ov = parse_overrides(args.overrides)
    for name in ("epochs", "seed", "time_budget"):
        v = getattr(args, name, None)
        if v is not None:
            ov[name] = v
    if getattr(args, "threads", None) is not None:
        ov["num_threads"] = args.threads
    return ov


def _report(s: dict) -> None:
    if int(os.environ.get("RANK", "0")) == 0:
        extra = f", val ADD(-S) {s['val_add']:.1f} %" if s.get("val_add") is not None else ""
        stop = " (stopped on the time budget)" if s["stopped_early"] else ""
        print(f"trained {s['kind']}: {s['steps']} step(s), epochs {s['start_epoch']}->{s['epochs']}{stop}, loss "
              f"{s['first_loss']:.4f} -> {s['last_loss']:.4f} m{extra}, {s['seconds']:.0f} s; run in {s['run_dir']}")


def _precheck(args, pfn) -> dict:
    """The overrides, checked against the profile's config before anything is read or written (a bad
    ``--set`` leaves no half-made run directory); on ``--resume`` the run's own config is checked by training."""
    ov = _overrides(args)
    if not args.resume:
        pfn(args.profile or "smoke", ov)
    return ov


def _cmd_train_pose(args) -> int:
    from .config import profile_config
    from .train import train_pose

    setup_logging(args.verbose)
    ov = _precheck(args, profile_config)
    s = train_pose(args.data, args.out, profile=args.profile, resume=args.resume, masks=args.masks, val=args.val,
                   device=args.device, progress=not args.no_progress, **ov)
    _report(s)
    return 0


def _cmd_train_refiner(args) -> int:
    from .config import refiner_profile_config
    from .train import train_refiner

    setup_logging(args.verbose)
    ov = _precheck(args, refiner_profile_config)
    s = train_refiner(args.pose, args.data, args.out, profile=args.profile, resume=args.resume, val=args.val,
                      device=args.device, progress=not args.no_progress, **ov)
    _report(s)
    return 0


def _cmd_predict(args) -> int:
    from ..artifacts.poses import RESULTS_HEADER, write_results, write_results_config
    from ..fileio import claim_output_file
    from .infer import check_inference_overrides, predict_dataset

    setup_logging(args.verbose)
    overrides = check_inference_overrides(parse_overrides(args.overrides))  # a bad --set fails before any work
    out = Path(args.out)
    claim_output_file(out, RESULTS_HEADER)  # refuse a foreign file before any work
    O.set_threads(args.threads)
    rows, est = predict_dataset(
        args.data,
        args.pose,
        refiner=args.refiner,
        masks=args.masks,
        iterations=args.iterations,
        icp=args.icp,
        colour_verify=args.colour_verify,
        verify=args.verify,
        device=args.device,
        split=args.split,
        limit=args.limit,
        score_thresh=args.score_thresh,
        progress=not args.no_progress,
        overrides=overrides,
        fallback=args.fallback,
        fallback_profile=args.fallback_profile,
    )
    write_results(rows, out)
    settings = dict(est.settings(), data=str(args.data), masks=args.masks, split=args.split, limit=args.limit)
    write_results_config(out, settings)
    failed = sum(1 for r in rows if r.score == 0)
    times = {(r.scene_id, r.im_id): r.time for r in rows}
    fps = len(times) / sum(times.values()) if times and sum(times.values()) > 0 else float("nan")
    fb = (f"; fallback {est.fallback} on {est.fallback_tried} instance(s), better on {est.fallback_won}"
          if est.fallback else "")
    onb = f" (objects' onboarding {est.onboarding_s:.1f} s apart)" if est.onboarding_s else ""
    print(f"{len(rows)} estimate(s) on {len(times)} image(s) ({failed} without an estimate), {fps:.2f} FPS{onb}{fb}; "
          f"wrote {out}")
    return 0


def _cmd_ablation(args) -> int:
    from ..artifacts.results import write_result
    from ..artifacts.tables import write_table
    from ..errors import ConfigError
    from ..fileio import claim_output_dir
    from .ablation import REFINER_VARIANTS, VARIANTS, run_ablation

    setup_logging(args.verbose)
    names = list(VARIANTS)
    if args.variants:
        try:
            picked = [names[int(k)] for k in args.variants.split(",")]
        except (ValueError, IndexError):
            raise ConfigError(
                f"--variants: comma-separated indices 0-{len(names) - 1}, got {args.variants!r}"
            ) from None
    else:
        picked = names
    if (args.epochs is None) == (args.time_budget is None):
        raise ConfigError(
            "give the budget of every variant: --epochs N (equal steps) or --time-budget SECONDS (equal time)"
        )
    budget = (
        {"epochs": args.epochs, "time_budget": 0.0} if args.epochs is not None else {"time_budget": args.time_budget}
    )
    overrides = parse_overrides(args.overrides)
    from .config import profile_config

    profile_config(args.profile, {**overrides, **budget})  # a bad --set fails before anything is written
    result_name = args.result_name or f"pose_ablation_{args.profile}"
    if not args.no_result:
        from ..artifacts.results import result_path
        from ..fileio import check_output_location

        check_output_location(result_path(result_name, args.results_dir), directory=False)
    claim_output_dir(args.out, "pose-ablation")  # refuse a foreign directory before any work
    table = run_ablation(args.data, args.val, args.out, profile=args.profile, variants={n: VARIANTS[n] for n in picked},
                         min_px=args.min_px, val_images=args.limit, progress=not args.no_progress,
                         seeds=range(args.seeds), refiner_variants=REFINER_VARIANTS if args.refiner_noise else None,
                         **budget, **overrides)
    out = Path(args.out)
    write_table(table, list(table.columns), out / "ablation.csv", out / "ablation.tex")
    print(table.to_string(index=False))
    if not args.no_result:
        path = write_result(result_name, table,
                            units={"train_seconds": "s", "val_add": "%", "n_val": "GT instances"},
                            description=f"pose ablation: each variant trained on {args.data} ({budget}, "
                                        f"{args.seeds} seed(s)), ADD(-S) on {args.val} (GT masks, >= {args.min_px} "
                                        "visible px; mean and sample standard deviation over the seeds)",
                            config={"profile": args.profile, **budget, **overrides, "seeds": args.seeds,
                                    "refiner_noise": bool(args.refiner_noise)},
                            results_dir=args.results_dir)
        print(f"result -> {path}")
    return 0


def _train_args(p, refiner: bool) -> None:
    O.add(p, "--data", help="training dataset (synthetic layout or BOP root), e.g. data/train")
    O.add(p, "--out", help="run directory (config.json, metrics.csv, last.pt, model.pt)")
    O.add_profile(p, REFINER_PROFILES if refiner else PROFILES,
                  help="named config (default smoke; on --resume: the run's)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its last completed epoch")
    O.add(p, "--val")
    O.add(p, "--epochs", help="number of epochs (may be raised on --resume)")
    O.add(p, "--time-budget", help="seconds; once spent (checked every step) the epoch ends early and training stops "
                                   "(0: none)")
    O.add(p, "--seed", help="seed of initialisation, shuffling and sampling")
    O.add_many(p, "--threads", "--device", "--no-progress")
    O.add(p, "--verbose", help="log every epoch")
    add_set_option(p)


def register(subparsers) -> None:
    """Add ``train-pose``, ``train-refiner``, ``predict-pose`` and ``pose-ablation`` to the ``sixdpose`` parser."""
    p = subparsers.add_parser("train-pose", help="train the learned pose network (paper IV-C)",
                              description="Train the DenseFusion-like pose network (PSPNet/ResNet-18 colour embedding, "
                              "point fusion, attention pooling). Profiles: smoke (CI), cpu (2 h on 2 cores with the "
                              "refiner), paper (GPU). Multi-process: run under torchrun.")
    _train_args(p, False)
    O.add(p, "--masks")
    p.set_defaults(func=_cmd_train_pose)

    p = subparsers.add_parser("train-refiner", help="train the iterative refiner on a trained pose network",
                              description="Train the refiner on the (noised) poses of a finished train-pose run.")
    O.add(p, "--pose")
    _train_args(p, True)
    p.set_defaults(func=_cmd_train_refiner)

    p = subparsers.add_parser("predict-pose", help="estimate poses with a trained pose network (BOP results CSV)",
                              description="Estimate the pose of every masked instance; writes a BOP results CSV "
                              "(score-0 rows for unusable instances) and <out stem>.config.yml beside it.")
    O.add(p, "--data")
    O.add(p, "--pose")
    p.add_argument("--refiner", default=None, help="run directory of train-refiner")
    p.add_argument("--iterations", type=O.Int(0, RefinerConfig.__dataclass_fields__["iterations"].metadata["max"]),
                   default=None, help="refinement iterations (default: the refiner's, 2; 0: none)")
    O.add(p, "--masks")
    O.add(p, "--score-thresh")
    p.add_argument("--icp", action="store_true", help="refine every pose with Open3D ICP (the hybrid stage's)")
    p.add_argument("--colour-verify", dest="colour_verify", action="store_true",
                   help="then run the hybrid stage's colour verification")
    O.add(p, "--verify")
    p.add_argument("--fallback", choices=list(HYBRID_ALGORITHMS), default=None,
                   help="with --verify: register the instances whose verified pose scores below verify_retry_below "
                        "(0.6) with this hybrid method too, verified, and keep the better pose (a cascade: the "
                        "network where it fits the frame, the slower search where it does not)")
    p.add_argument("--fallback-profile", dest="fallback_profile", choices=[n for n in PRESETS if n != "paper"],
                   default="fast",
                   help="the fallback's registration preset (default: fast)")
    O.add(p, "--split")
    O.add(p, "--limit")
    O.add(p, "--out", help="results CSV to write")
    O.add_many(p, "--threads", "--device", "--no-progress")
    O.add(p, "--verbose", help="log every score-0 row's reason")
    add_set_option(p)
    p.set_defaults(func=_cmd_predict)

    from .ablation import VARIANTS

    p = subparsers.add_parser(
        "pose-ablation",
        help="train each option of the paper's architecture alone and score it on val",
        description="The ablation of section IV-C's choices: each variant (indices: "
        + "; ".join(f"{k} {n}" for k, n in enumerate(VARIANTS))
        + ") trained on --data with the same "
        "budget and scored by ADD(-S) on --val (never test). Resumable: finished variants are "
        "scored, not retrained. Writes OUT/<k>_<variant>/ runs, OUT/ablation.csv/.tex and the "
        "result artifact RESULTS_DIR/NAME.json.",
    )
    O.add(p, "--data", help="training dataset, e.g. data/train")
    O.add(p, "--val", required=True, help="held-out dataset the variants are scored on, e.g. data/val (never test)")
    O.add(p, "--out", help="directory of the variants' runs")
    O.add_profile(p, PROFILES, help="base PoseConfig profile")
    O.add(p, "--epochs", help="epochs per variant (equal steps; time budget off)")
    O.add(p, "--time-budget", help="seconds of training per variant (equal time)")
    p.add_argument("--variants", default=None, help="comma-separated variant indices (default: all)")
    p.add_argument("--seeds", type=O.Int(1, 100), default=1,
                   help="train every variant with seeds 0..N-1; rows hold the mean, spread and per-seed ADD(-S)")
    p.add_argument("--refiner-noise", dest="refiner_noise", action="store_true",
                   help="also train the refiner with the paper's pose noise and without, on each seed's network of "
                        "the first variant, scored after 2 iterations (the paper's claim of section IV-C5)")
    O.add(p, "--limit")
    O.add(p, "--min-px")
    O.add(p, "--results-dir", help="directory of the result artifact (default: results)")
    O.add(p, "--result-name", help="result name (default: pose_ablation_<profile>)")
    p.add_argument("--no-result", action="store_true", help="write no result artifact")
    O.add(p, "--no-progress")
    O.add(p, "--verbose")
    add_set_option(p)
    p.set_defaults(func=_cmd_ablation)
