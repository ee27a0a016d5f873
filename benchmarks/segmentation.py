"""Benchmark of Mask R-CNN inference: images/s and peak memory, on CPU and (when present) on the GPU.

Usage::

    python benchmarks/segmentation.py [--ckpt RUN_DIR | --profile paper|smoke] [--data DIR]
                                      [--n-images 8] [--batch-size 1] [--threads N] [--json OUT]
                                      [--results-dir results] [--result-name segmentation_<profile or run>]
                                      [--no-result]

Without ``--ckpt`` an untrained network of the profile's architecture is timed (``paper``: ResNet-50-FPN
at 640x480, the paper's model); its random weights give an arbitrary number of detections (often the
maximum, 100 per image), so the post-processing cost differs from a trained run's. Without ``--data`` a toy
640x480 dataset is written to a temporary directory. Timings exclude reading images from disk (as in the
paper, section V-A): images are loaded before the clock starts; the time covers the forward pass including
resizing, post-processing and pasting the masks back at full resolution, and the copy of the results to the CPU.

Peak memory: on CPU the increase of the process' peak resident set size during the timed runs (MiB;
the model's weights are loaded before); on the GPU ``torch.cuda.max_memory_allocated``.

One row per device is also written as the result artifact ``results/segmentation_<profile>.json``
(``segmentation_<run dir name>`` with ``--ckpt``).
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import tempfile
import time
from pathlib import Path


def _peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def bench_device(seg, rgbs: list, batch_size: int, warmup: int) -> dict:
    """Time ``seg.predict`` over ``rgbs`` on the segmenter's device; returns images/s and peak memory."""
    import torch

    cuda = seg.device.type == "cuda"
    batches = [rgbs[i : i + batch_size] for i in range(0, len(rgbs), batch_size)]
    for b in batches[:warmup]:
        seg.predict(b)
    if cuda:
        torch.cuda.synchronize()
        torch.cuda.reset_peak_memory_stats()
    rss0 = _peak_rss_mib()
    n_det = 0
    t0 = time.perf_counter()
    for b in batches:
        for p in seg.predict(b):  # results are on the CPU when predict returns
            n_det += len(p["labels"])
    if cuda:
        torch.cuda.synchronize()
    dt = time.perf_counter() - t0
    out = {
        "device": str(seg.device),
        "images": len(rgbs),
        "batch_size": batch_size,
        "seconds": dt,
        "images_per_s": len(rgbs) / dt,
        "ms_per_image": 1000.0 * dt / len(rgbs),
        "detections": n_det,
    }
    if cuda:
        out["peak_gpu_mib"] = torch.cuda.max_memory_allocated() / 2**20
        out["gpu"] = torch.cuda.get_device_name(seg.device)
    else:
        out["peak_rss_increase_mib"] = max(_peak_rss_mib() - rss0, 0.0)
        out["threads"] = torch.get_num_threads()
    out["peak_rss_mib"] = _peak_rss_mib()
    return out


def untrained_checkpoint(profile: str, ds, path: Path, seed: int = 0) -> tuple[Path, str]:
    """Write a randomly initialised Mask R-CNN of the segmentation ``profile`` (no pretrained weights; the
    classes of the dataset reader ``ds``) as a checkpoint at ``path``; returns ``(path, label)``."""
    import torch

    from sixdpose.runs import save_checkpoint
    from sixdpose.segmentation import checkpoint as ck
    from sixdpose.segmentation.config import profile_config
    from sixdpose.segmentation.data import ClassMap
    from sixdpose.segmentation.model import build_model

    cfg = profile_config(profile, pretrained=False)
    classes = ClassMap.from_dataset(ds)
    torch.manual_seed(seed)
    model, init = build_model(cfg, len(classes))
    save_checkpoint(ck.weights(cfg, classes.to_list(), init, model.state_dict()), path)
    return path, f"untrained {profile} model ({cfg.backbone}, {len(classes)} classes, random weights)"


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print one line per device (and JSON with ``--json``)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ckpt", help="trained run directory or checkpoint (default: untrained --profile model)")
    ap.add_argument("--profile", default="paper", choices=("paper", "smoke"))
    ap.add_argument("--data", help="dataset directory (default: a temporary toy dataset)")
    ap.add_argument("--split", default="test", help="BOP split")
    ap.add_argument("--n-images", type=int, default=8)
    ap.add_argument("--batch-size", type=int, default=1)
    ap.add_argument("--warmup", type=int, default=1, help="untimed batches first")
    ap.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: default)")
    ap.add_argument("--devices", default="cpu,cuda", help="comma-separated; cuda is skipped when absent")
    ap.add_argument("--json", help="also write the results here")
    from sixdpose.artifacts.results import add_result_arguments, save_from_args, script_command

    add_result_arguments(ap, None, Path(__file__).resolve().parents[1] / "results",
                         "segmentation_<profile or run dir name>")
    args = ap.parse_args(argv)
    if args.result_name is None:
        args.result_name = "segmentation_" + (Path(args.ckpt).resolve().name if args.ckpt else args.profile)

    import torch

    from sixdpose.datasets import open_dataset
    from sixdpose.segmentation.infer import Segmenter

    if args.threads:
        torch.set_num_threads(args.threads)
    tmp = tempfile.TemporaryDirectory(prefix="sixdpose_bench_")
    data = args.data
    if data is None:
        from sixdpose.segmentation.toydata import make_toy_dataset

        data = make_toy_dataset(Path(tmp.name) / "toy", n_scenes=1, views=max(args.n_images, 1), seed=0)
    ds = open_dataset(data, split=args.split)
    rgbs = [ds[i % len(ds)].rgb for i in range(args.n_images)]
    ckpt = args.ckpt
    label = f"checkpoint {ckpt}"
    if ckpt is None:
        ckpt, label = untrained_checkpoint(args.profile, ds, Path(tmp.name) / "model.pt")
    results = []
    for dev in [d.strip() for d in args.devices.split(",") if d.strip()]:
        if dev.startswith("cuda") and not torch.cuda.is_available():
            print(f"{dev}: not available, skipped")
            continue
        seg = Segmenter(ckpt, device=dev)
        r = bench_device(seg, rgbs, args.batch_size, args.warmup)
        r["model"] = label
        results.append(r)
        mem = (f"peak GPU memory {r['peak_gpu_mib']:.0f} MiB ({r['gpu']})" if "peak_gpu_mib" in r
               else f"peak RSS {r['peak_rss_mib']:.0f} MiB (+{r['peak_rss_increase_mib']:.0f} MiB during inference, "
                    f"{r['threads']} threads)")
        H, W = rgbs[0].shape[:2]
        print(f"{r['device']}: {r['images_per_s']:.2f} images/s ({r['ms_per_image']:.0f} ms/image, {W}x{H}, "
              f"batch {r['batch_size']}, {r['images']} images, {r['detections']} detections); {mem}; {label}")
        del seg
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1) + "\n")
    save_from_args(args, results, command=script_command(__file__, argv),
                   units={"seconds": "s", "images_per_s": "images/s", "ms_per_image": "ms", "peak_gpu_mib": "MiB",
                          "peak_rss_increase_mib": "MiB", "peak_rss_mib": "MiB"},
                   description=f"Mask R-CNN inference ({label}) on {args.n_images} "
                               f"{rgbs[0].shape[1]}x{rgbs[0].shape[0]} images "
                               f"({'toy data' if args.data is None else Path(args.data).name}), disk reads excluded",
                   config={"ckpt": args.ckpt, "profile": args.profile, "data": args.data, "split": args.split,
                           "n_images": args.n_images, "batch_size": args.batch_size, "warmup": args.warmup,
                           "threads": args.threads, "devices": args.devices})
    tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
