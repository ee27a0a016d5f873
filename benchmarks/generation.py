"""Benchmark of the synthetic dataset generator (issue: foundation, section 7).

Prints end-to-end images per second per core (physics, rendering and writing included) and the peak
memory of a scene worker. Runs ``--workers`` scene workers (default: one per core) on a fresh output
directory so nothing is resumed.

    .venv/bin/python benchmarks/generation.py [--scenes 6] [--views 20] [--workers N]
        [--results-dir results] [--result-name generation] [--no-result]

The paper reports 25,000 images in under a day on a 16-core CPU: about 0.02 images/s per core.
One row per sensor model is also written as the result artifact ``results/generation.json``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

from sixdpose.artifacts.results import add_result_arguments, save_from_args, script_command
from sixdpose.generation import generate, profile


def main(argv=None) -> None:
    """Run the benchmark, print its figures and write them as a result artifact."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=6)
    ap.add_argument("--views", type=int, default=20)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--assets", default=None)
    ap.add_argument("--sensors", default="ideal",
                    help="comma-separated depth sensor models to time on the same scenes, e.g. ideal,kinect")
    add_result_arguments(ap, "generation", Path(__file__).resolve().parents[1] / "results")
    args = ap.parse_args(argv)
    cores = os.cpu_count() or 1
    speed = {}
    rows = []
    for sensor in args.sensors.split(","):
        with tempfile.TemporaryDirectory() as tmp:
            cfg = profile("paper", scenes=args.scenes, views=args.views, seed=args.seed, sensor=sensor)
            r = generate(f"{tmp}/ds", cfg, workers=args.workers, assets=args.assets, progress=False)
        used = min(args.workers, cores, args.scenes)
        per_core_wall = r["images_per_s"] / used
        per_core_cpu = r["images"] / r["cpu_seconds"] if r["cpu_seconds"] else float("nan")
        speed[sensor] = per_core_cpu
        print(f"generation benchmark: {args.scenes} scenes x {args.views} views "
              f"(paper profile config, seed {args.seed}, sensor {sensor}), {args.workers} workers on {cores} cores")
        print(f"  images                      {r['images']}")
        print(f"  wall time                   {r['seconds']:.1f} s (includes worker start-up)")
        print(f"  images/s                    {r['images_per_s']:.2f}")
        print(f"  images/s per core (wall)    {per_core_wall:.2f}   [target >= 3; paper ~0.02]")
        print(f"  images/s per CPU-second     {per_core_cpu:.2f}   (scene workers' own CPU time)")
        print(f"  peak memory per worker      {r['peak_rss_mb']:.0f} MB")
        print(f"  failed scenes               {len(r['scenes_failed'])}")
        rows.append({"sensor": sensor, "scenes": args.scenes, "views": args.views, "workers": args.workers,
                     "images": r["images"], "wall_s": r["seconds"], "images_per_s": r["images_per_s"],
                     "images_per_s_per_core_wall": per_core_wall, "images_per_cpu_second": per_core_cpu,
                     "peak_rss_mb_per_worker": r["peak_rss_mb"], "failed_scenes": len(r["scenes_failed"])})
    if "ideal" in speed:
        for sensor, v in speed.items():
            if sensor != "ideal":
                print(f"  {sensor} speed / ideal speed (images per CPU-second): "
                      f"{v / speed['ideal']:.3f}   [target >= 0.8]")
    save_from_args(args, rows, command=script_command(__file__, argv),
                   units={"wall_s": "s", "images_per_s": "images/s", "images_per_s_per_core_wall": "images/s",
                          "images_per_cpu_second": "images/CPU-s", "peak_rss_mb_per_worker": "MB"},
                   description=f"synthetic generator end to end (physics, rendering, writing): {args.scenes} scenes x "
                               f"{args.views} views, paper profile config, seed {args.seed}, {args.workers} workers",
                   config={"scenes": args.scenes, "views": args.views, "workers": args.workers, "seed": args.seed,
                           "sensors": args.sensors.split(",")})


if __name__ == "__main__":
    main()
