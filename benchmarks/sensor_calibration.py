"""Calibration of the kinect depth model against real YCB-Video frames: hole statistics in object masks.

Measures, over the GT visible masks (:func:`sixdpose.generation.checks.depth_hole_stats`), the fraction
of masked pixels without depth, split into the 3 px rim of each mask and its interior, for

* the real frames of the YCB-Video sample, per scene (000000 is the tuning scene, 000001 is held out);
* an ideal-depth generated dataset (``generate --profile ycbv_ideal``) with the kinect model applied to
  its perfect depth exactly as the generator does (``sensor_rng(seed, scene, view)``, the view's rgb):
  simkinect's validity window (``KINECT_SIMKINECT``, the model before calibration), the model's
  defaults (the calibration), and with ``--grid`` a sweep of the window parameters and the baseline.

    nice -n 15 env PYTHONPATH=src python -m sixdpose generate --profile ycbv_ideal --scenes 3 --views 10 \\
        --out /tmp/sens_ideal --workers 1 --no-progress
    PYTHONPATH=src python benchmarks/sensor_calibration.py --ideal /tmp/sens_ideal \\
        [--real ../shared/data/ycbv_sample] [--grid] [--residual] [--no-result]

Prints the figures and writes them as the result artifact ``results/sensor_calibration.json``.
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

from sixdpose.artifacts.results import add_result_arguments, save_from_args, script_command
from sixdpose.datasets.readers import open_dataset
from sixdpose.generation.checks import depth_hole_stats
from sixdpose.generation.config import GenerationConfig
from sixdpose.generation.sensors import KINECT_SIMKINECT, kinect, sensor_rng, simulate_depth

GRID = {"window": (3, 5, 7, 9), "min_valid_fraction": (1 / 2, 2 / 3, 7 / 9, 1 / 1.2),
        "edge_threshold": (0.2, 0.25, 0.3, 0.6), "baseline": (0.05, 0.075)}


def kinect_depth_fn(reader, **params):
    """``f(sample) -> depth``: the kinect model with ``params`` applied to a generated dataset's ideal
    depth with the generator's own per-view stream (seed and views from its ``manifest.json``)."""
    cfg = GenerationConfig.from_dict(reader.manifest["config"])

    def f(s):
        return simulate_depth(s.depth, s.K, "kinect", sensor_rng(cfg.seed, s.scene_id, s.im_id % cfg.views),
                              rgb=s.rgb, **params)

    return f


def _defaults() -> dict:
    """The window parameters of :func:`kinect`'s defaults (the calibration)."""
    import inspect

    sig = inspect.signature(kinect)
    return {k: sig.parameters[k].default for k in KINECT_SIMKINECT}


def _row(depth: str, setting: str, st: dict) -> dict:
    """A result row: hole fractions in percent."""
    row = {"depth": depth, "setting": setting, "images": st["images"], "instances": st["instances"],
           "hole": 100 * st["hole"], "rim_hole": 100 * st["edge_hole"], "interior_hole": 100 * st["interior_hole"]}
    if "residual_median" in st:
        row["residual_median"] = 1e3 * st["residual_median"]
    return row


def _line(name: str, st: dict) -> str:
    res = f"  {1e3 * st['residual_median']:6.2f}" if "residual_median" in st else ""
    return (f"  {name:<44} {st['images']:4d} {st['instances']:5d} {100 * st['hole']:7.2f} "
            f"{100 * st['edge_hole']:7.2f} {100 * st['interior_hole']:7.2f}{res}")


def main(argv=None) -> None:
    """Measure the real and simulated hole fractions, print them and write the result artifact."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sample = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "ycbv_sample"
    ap.add_argument("--real", default=str(sample),
                    help="BOP dataset root with a train_real split (the YCB-Video sample)")
    ap.add_argument("--ideal", required=True, help="a dataset generated with sensor=ideal (profile ycbv_ideal)")
    ap.add_argument("--tune-scene", type=int, default=0)
    ap.add_argument("--grid", action="store_true", help="also sweep the window parameters and the baseline")
    ap.add_argument("--residual", action="store_true", help="also the median distance to the model points (mm)")
    add_result_arguments(ap, "sensor_calibration", Path(__file__).resolve().parents[1] / "results")
    args = ap.parse_args(argv)
    real = open_dataset(args.real, split="train_real")
    ideal = open_dataset(args.ideal)
    if ideal.manifest.get("config", {}).get("sensor") != "ideal":
        raise SystemExit(f"{args.ideal}: not an ideal-depth dataset (config sensor must be 'ideal')")
    rows = []
    print(f"  {'depth':<44} {'imgs':>4} {'inst':>5} {'hole %':>7} {'rim %':>7} {'inner %':>7}"
          + ("  res mm" if args.residual else ""))
    scenes = sorted({k[0] for k in list(real.keys())})
    for sc in scenes:
        st = depth_hole_stats(real, scenes=[sc], residual=args.residual)
        tag = "tuning" if sc == args.tune_scene else "held out"
        rows.append(_row(f"real, scene {sc:06d} ({tag})", "", st))
        print(_line(rows[-1]["depth"], st))
    settings = [("kinect, simkinect window (before)", dict(KINECT_SIMKINECT)), ("kinect, defaults (calibrated)", {})]
    if args.grid:
        keys = list(GRID)
        settings += [(" ".join(f"{k}={v:.3g}" for k, v in zip(keys, vals, strict=True)),
                      dict(zip(keys, vals, strict=True)))
                     for vals in itertools.product(*GRID.values())]
    for name, params in settings:
        st = depth_hole_stats(ideal, depth_fn=kinect_depth_fn(ideal, **params), residual=args.residual)
        setting = ", ".join(f"{k} {v:.3g}" for k, v in (params or _defaults()).items())
        rows.append(_row(f"sim {name}", setting, st))
        print(_line(rows[-1]["depth"], st), flush=True)
    save_from_args(args, rows, command=script_command(__file__, argv),
                   units={"hole": "% of masked px", "rim_hole": "% of 3 px rim px",
                          "interior_hole": "% of interior px", "residual_median": "mm"},
                   description="depth holes inside GT visible masks: real YCB-Video sample vs the kinect model "
                               "applied to an ideal generated dataset",
                   config={"real": str(args.real), "ideal": str(args.ideal), "tune_scene": args.tune_scene,
                           "grid": args.grid})


if __name__ == "__main__":
    main()
