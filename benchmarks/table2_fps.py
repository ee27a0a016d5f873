"""Table II as the paper measured it: end-to-end frames per second of every method, overheads included.

Usage::

    python benchmarks/table2_fps.py [--data ../shared/data/ycbv_sample] [--split train_real] [--frames 4]
        [--seg SEG_RUN | --seg-profile paper|smoke] [--pose POSE_RUN --refiner REFINER_RUN | --pose-profile paper|cpu]
        [--methods ransac_icp,fgr_icp,super4pcs_icp,learned_it0,learned_it2] [--preset default|paper]
        [--min-px 0] [--threads N] [--out results/<profile>/table2_fps.json]

The paper's section V-A: the FPS of a method includes all of its overheads. Per method, on the same
frames, loaded into memory before any clock starts (disk reads excluded; the first frame is an untimed
warm-up that also builds the object models' references, an offline step):

* ``e2e_fps``: the whole frame: the Mask R-CNN forward on the RGB image (resize, backbone, heads,
  post-processing, masks pasted at full resolution), then the method on the frame's instances. Hybrid
  methods: back-projection, scene gating and downsampling, normals, FPFH features (RANSAC, FGR),
  the global registration, ICP and the ``default`` preset's colour verification, through the same
  per-frame code as ``sixdpose register`` (:func:`sixdpose.registration.runner.process_image`). Learned
  methods: point sampling, crops, the pose network and (``learned_it2``) two refinement iterations,
  through :meth:`sixdpose.pose.Estimator.predict` as ``sixdpose predict-pose``.
* ``pose_fps``: the pose stage alone on the ground-truth masks (what ``register`` / ``predict-pose``
  record per image and the results' ``fps`` figure reports).

Which masks the pose stage gets after segmentation: with ``--seg`` (a trained run) its detections scoring
>= 0.5, as the graph; without it a randomly initialised Mask R-CNN of ``--seg-profile`` (``paper``:
ResNet-50-FPN, the paper's model; the forward's cost does not depend on the weights, but its detections
are noise), so its forward is timed and the pose stage then gets the ground-truth masks. Without
``--pose`` the learned rows time untrained networks of ``--pose-profile`` (the cost does not depend on the
weights either). Every row says which.

Prints the table; ``--out PATH.json`` also writes it as a result artifact (``sixdpose.artifacts.results``:
commit, date, machine, command), which notebook 07 uses for the write-up's Table II when it lies in the
profile's results directory as ``table2_fps.json``.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from sixdpose.constants import MIN_DETECTION_SCORE  # noqa: E402


def _bench(name: str):
    """The benchmark script ``benchmarks/<name>.py`` as a module (its functions are reused, not copied)."""
    spec = importlib.util.spec_from_file_location(f"_bench_{name}", ROOT / "benchmarks" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


#: method key -> (kind, registration method, icp) or (kind, refinement iterations)
HYBRID = {"ransac_icp": ("ransac", True), "fgr_icp": ("fgr", True), "super4pcs_icp": ("super4pcs", True),
          "ransac": ("ransac", False), "fgr": ("fgr", False), "super4pcs": ("super4pcs", False)}
LEARNED = {"learned_it0": 0, "learned_it2": 2}


class FrameReader:
    """A dataset reader serving one in-memory frame (``current``) with the models of ``reader``: the
    registration runner's per-frame code then reads nothing from disk inside the clock."""

    def __init__(self, reader):
        self.reader, self.current = reader, None
        self.has_depth, self.has_masks = True, True

    def __len__(self) -> int:
        return 1

    def __getitem__(self, index: int):
        return self.current

    def keys(self) -> list:
        """The one key of the current frame."""
        return [(self.current.scene_id, self.current.im_id)]

    @property
    def object_ids(self) -> dict:
        """The models' ids of the underlying reader."""
        return self.reader.object_ids

    def model(self, obj_id: int):
        """The underlying reader's model of ``obj_id`` (read once, cached by the caller)."""
        return self.reader.model(obj_id)

    def is_symmetric(self, obj_id: int) -> bool:
        """As the underlying reader."""
        return self.reader.is_symmetric(obj_id)


def with_instances(sample, instances):
    """``sample`` with its instances replaced (the arrays shared, nothing copied)."""
    from dataclasses import replace

    return replace(sample, instances=list(instances))


def detections_as_instances(out: dict, min_score: float) -> list:
    """The Mask R-CNN output of one image (``labels``, ``scores``, ``masks``) as instances (pose unknown)
    for the registration runner's GT-mask path, those scoring at least ``min_score``."""
    import numpy as np

    from sixdpose.datasets.base import Instance

    return [Instance(f"obj_{int(o):06d}", int(o), k, np.eye(3), np.zeros(3), m.astype(bool), -1)
            for k, (o, s, m) in enumerate(zip(out["labels"], out["scores"], out["masks"], strict=True))
            if float(s) >= min_score]


def hybrid_stage(frames: FrameReader, algo: str, icp: bool, cfg):
    """A function ``f(sample) -> rows`` registering every instance of ``sample`` (its masks) with the
    runner's per-frame code, in this process."""
    from sixdpose.registration import runner

    runner._init_worker(frames, algo, icp, cfg, "gt", 0, MIN_DETECTION_SCORE)

    def run(sample):
        frames.current = sample
        return runner.process_image(0)[0]

    return run


def learned_stage(est):
    """A function ``f(sample) -> rows`` running :meth:`Estimator.predict` on ``sample``'s masks."""
    return lambda sample: est.predict(sample)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data" / "ycbv_sample"),
                    help="a BOP or generated dataset with depth (default: ../shared/data/ycbv_sample)")
    ap.add_argument("--split", default="train_real", help="BOP split (default: train_real)")
    ap.add_argument("--frames", type=int, default=4, help="timed frames (plus one untimed warm-up; default 4)")
    ap.add_argument("--stride", type=int, default=1, help="every N-th frame of the split (default 1)")
    ap.add_argument("--seg", help="a trained segmentation run (default: a random-weight model of --seg-profile)")
    ap.add_argument("--seg-profile", default="paper", choices=("paper", "smoke"))
    ap.add_argument("--pose", help="a trained pose run (default: untrained networks of --pose-profile)")
    ap.add_argument("--refiner", help="its refiner run (with --pose)")
    ap.add_argument("--pose-profile", default="paper", choices=("paper", "cpu", "smoke"))
    ap.add_argument("--methods", default="ransac_icp,fgr_icp,super4pcs_icp,learned_it0,learned_it2",
                    help=f"comma-separated, of {', '.join([*HYBRID, *LEARNED])}")
    ap.add_argument("--preset", default="default", choices=("default", "paper"), help="registration preset")
    ap.add_argument("--min-px", type=int, default=0, help="GT instances with fewer visible pixels are left out")
    ap.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: torch's default)")
    ap.add_argument("--symmetric-ids", default=None, help="BOP only: obj_ids treated as symmetric")
    ap.add_argument("--out", help="also write the table as a result artifact here (e.g. results/cpu/table2_fps.json)")
    args = ap.parse_args(argv)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    bad = [m for m in methods if m not in HYBRID and m not in LEARNED]
    if bad or args.frames < 1 or args.stride < 1:
        ap.error(f"unknown method(s) {bad}" if bad else "--frames and --stride must be >= 1")
    if args.refiner and not args.pose:
        ap.error("--refiner needs --pose")

    import torch

    from sixdpose.datasets import open_dataset
    from sixdpose.errors import SixdposeError
    from sixdpose.pose.infer import Estimator
    from sixdpose.registration.presets import get_preset
    from sixdpose.segmentation.infer import Segmenter

    pose_bench, seg_bench = _bench("pose"), _bench("segmentation")
    if args.threads:
        torch.set_num_threads(args.threads)
    device = torch.device("cpu")
    tmp = tempfile.TemporaryDirectory(prefix="sixdpose_table2_")
    try:
        kw = {"symmetric_ids": [int(x) for x in args.symmetric_ids.split(",")]} if args.symmetric_ids else {}
        reader = open_dataset(args.data, split=args.split, **kw)
        keys = reader.keys()[:: args.stride][: args.frames + 1]
        # disk reads before any clock: the frames, their GT instances (>= --min-px), every model they show
        samples = []
        for k in keys:
            s = reader.load(k)
            samples.append(with_instances(s, [i for i in s.instances if i.px_visib < 0 or i.px_visib >= args.min_px]))
        for oid in sorted({i.obj_id for s in samples for i in s.instances}):
            reader.model(oid)
        if args.seg:
            seg_ckpt, seg_label = args.seg, f"trained run {args.seg} (its detections >= {MIN_DETECTION_SCORE})"
        else:
            seg_ckpt, seg_label = seg_bench.untrained_checkpoint(args.seg_profile, reader, Path(tmp.name) / "seg.pt")
            seg_label += "; forward timed, then the pose stage on GT masks"
        segm = Segmenter(seg_ckpt, device="cpu")
        if args.pose:
            pose_run, ref_run, pose_label = args.pose, args.refiner, f"trained run {args.pose}"
        else:
            pose_run, ref_run = pose_bench.fake_runs(args.pose_profile, Path(tmp.name))
            pose_label = f"untrained {args.pose_profile} networks"
    except (SixdposeError, OSError) as e:
        print(f"table2_fps: {e}", file=sys.stderr)
        return 1

    frames = FrameReader(reader)
    seg_times: list[float] = []

    def segment(sample):
        t0 = time.perf_counter()
        out = segm.predict([sample.rgb])[0]
        seg_times.append(time.perf_counter() - t0)
        return with_instances(sample, detections_as_instances(out, MIN_DETECTION_SCORE)) if args.seg else sample

    rows = []
    cfg = get_preset(args.preset)
    for m in methods:
        if m in HYBRID:
            algo, icp = HYBRID[m]
            stage, label = hybrid_stage(frames, algo, icp, cfg), f"register --method {algo}" + (" --icp" if icp else "")
            label += f"{'' if cfg.verify else ' --no-verify'} (preset {args.preset})"
        else:
            it = LEARNED[m]
            if it and ref_run is None:
                print(f"{m}: skipped (no --refiner)")
                continue
            est = Estimator(pose_run, ref_run if it else None, iterations=it, device="cpu", reader=reader)
            stage, label = learned_stage(est), f"predict-pose --iterations {it} ({pose_label})"
        stage(samples[0])  # warm-up: references, first-call allocations, the colour kernel
        pose_t = pose_bench.timed(stage, samples[1:], device)
        segment(samples[0])
        seg_times.clear()
        e2e_t = pose_bench.timed(lambda s, st=stage: st(segment(s)), samples[1:], device)
        n = len(pose_t)
        n_inst = sum(len(s.instances) for s in samples[1:])
        rows.append({"method": m, "command": label, "frames": n, "instances": n_inst,
                     "e2e_fps": n / sum(e2e_t), "pose_fps": n / sum(pose_t),
                     "seg_ms_per_frame": 1000 * sum(seg_times) / n, "e2e_ms_per_frame": 1000 * sum(e2e_t) / n,
                     "pose_ms_per_frame": 1000 * sum(pose_t) / n})
        r = rows[-1]
        print(f"{m:15s} end-to-end {r['e2e_fps']:6.3f} FPS ({r['e2e_ms_per_frame']:7.0f} ms/frame, segmentation "
              f"{r['seg_ms_per_frame']:6.0f} ms)   pose stage only {r['pose_fps']:6.3f} FPS "
              f"({r['pose_ms_per_frame']:6.0f} ms/frame, {n_inst / n:.1f} instances/frame)", flush=True)
    threads = torch.get_num_threads()
    load = os.getloadavg()[0]  # other jobs on the machine slow every row alike; the record says how busy it was
    print(f"\n{len(samples) - 1} frames of {args.data} ({args.split}), disk reads excluded; Mask R-CNN: {seg_label}; "
          f"learned: {pose_label}; torch threads {threads}, {os.cpu_count()} CPUs, load average {load:.1f}")
    print(f"\n{'method':15s} {'e2e FPS':>8s} {'pose-stage FPS':>15s}")
    for r in rows:
        print(f"{r['method']:15s} {r['e2e_fps']:8.3f} {r['pose_fps']:15.3f}")
    if args.out:
        from sixdpose.artifacts.results import script_command, write_result

        out = Path(args.out)
        if out.suffix != ".json":
            print(f"table2_fps: --out {out}: expected a .json path", file=sys.stderr)
            return 1
        write_result(out.stem, rows, results_dir=out.parent, command=script_command(__file__, argv),
                     units={"e2e_fps": "frames/s", "pose_fps": "frames/s", "seg_ms_per_frame": "ms",
                            "e2e_ms_per_frame": "ms", "pose_ms_per_frame": "ms"},
                     description=f"end-to-end FPS (Mask R-CNN + pose stage) and pose-stage FPS per method on "
                                 f"{len(samples) - 1} frames of {Path(args.data).name}/{args.split}, disk reads "
                                 f"excluded",
                     config={"data": args.data, "split": args.split, "frames": args.frames, "stride": args.stride,
                             "segmentation": seg_label, "pose": pose_label, "preset": args.preset,
                             "min_px": args.min_px, "threads": threads, "methods": methods},
                     notes=f"load average {load:.2f} over the last minute at the end of the run, on {os.cpu_count()} "
                           "CPUs: other jobs running at the same time lower every figure")
        print(f"wrote {out}")
    tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
