"""Benchmark of the learned pose stage: training throughput and end-to-end inference FPS.

Usage::

    python benchmarks/pose.py [--profile cpu|smoke|paper] [--head paper|dense] [--pose RUN --refiner RUN2]
                              [--device cpu|cuda]
                              [--instances 6] [--frames 10] [--repeats 1] [--steps 10] [--threads N]
                              [--json OUT]
                              [--seg SEG_RUN | --seg-profile cpu|smoke|paper [--seg-backbone B]]
                              [--seg-set FIELD=VALUE ...] [--data DIR[@SPLIT]] [--amp | --no-amp | --fp32]
                              [--slides SLIDES.npz | --save-slides SLIDES.npz]
                              [--results-dir results] [--result-name pose_<profile>_<device>] [--no-result]

* Training throughput (instances/s): optimiser steps of the main network and of the refiner
  (2 unrolled iterations) for the profile's config and batch size, on synthetic inputs (random crops
  or full images, the profile's point counts), after 2 warm-up steps.
* Inference FPS (paper section V-A): :meth:`Estimator.predict` on one 640x480 RGB-D frame holding
  ``--instances`` masked objects: point sampling, crops, one batched forward of every instance, 2
  refinement iterations, copies to the CPU (``--head dense``: the dense head's per-point coordinates
  and its RANSAC + weighted Kabsch fit per instance instead of the refiner; its training step is the
  dense loss on random targets, and it has no refiner). Frames are built in memory beforehand (no disk reads);
  segmentation is not included. Without ``--pose`` untrained networks of the profile are timed
  (the cost does not depend on the weights).
* With ``--data DIR[@SPLIT]`` (a trained ``--pose``) the inference FPS is measured on the dataset's first
  ``--frames`` frames with their ground-truth masks instead (the reader given to the estimator: a run that
  names its shape flips by the models' colours does so). ``--appearance local|none`` (with ``--head dense``)
  times untrained networks without the CNN (``PoseConfig.appearance``); a trained run is timed with its own.
* With ``--seg SEG_RUN --data DIR`` (trained runs): end-to-end FPS on the dataset's first ``--frames``
  real frames, loaded into memory first: Mask R-CNN on the RGB image, then the pose network and 2
  refinement iterations on every detection of the frame in one batch (section V-A: disk reads excluded).
  The reported pass' two parts are given too (``e2e_seg_ms_per_frame``: Mask R-CNN and its detections;
  ``e2e_pose_ms_per_frame``: the pose stage on them).
  Mask R-CNN keeps only the detections the pose stage uses (score >= ``MIN_DETECTION_SCORE``): the pose
  stage's poses are the same, and no mask is pasted for a detection it would drop. On the CPU the Segmenter
  runs its backbone compiled (:func:`sixdpose.segmentation.infer.optimise_backbone`: the same detections).
* Onboarding is not timed: with ``--data``, every frame is run once untimed before the timed pass, so each
  object's one-time model reads and model-side data (its onboarding, which ``predict-pose`` also leaves out
  of its per-image times, as BOP 2023 times it apart) are done before the clock, as in a deployment that
  knows its objects in advance.
* With ``--seg-profile PROFILE --data DIR`` instead (no trained segmentation run at hand, e.g. on a lent GPU
  machine): end-to-end FPS with an untrained Mask R-CNN of that segmentation profile's architecture, made to
  return as many detections as the frame has objects (score threshold 0, ``detections_per_img`` = the
  frame's instance count), so its cost is that of a trained network finding them; the pose stage then runs
  on the frame's ground-truth masks (an untrained network's masks are noise). The cost of Mask R-CNN does
  not depend on its weights once the number of detections is fixed. ``--seg-backbone`` replaces that
  profile's backbone (``mobilenet_v3_large``: the ``cpu`` graph's real-time segmenter); ``--seg-set`` changes
  the Mask R-CNN's inference fields (``amp=false``: float32 on a GPU).
* ``--amp`` / ``--no-amp`` (``--fp32``): the pose networks in half or single precision on a GPU (default: the
  estimator's, :attr:`Estimator.amp`: float32 for the dense head since session 31, half for the paper head).
* A machine without Open3D (a lent GPU machine) cannot build the colour-named slides (model-side data made
  with Open3D's voxel grid): ``--save-slides FILE`` writes those of ``--data``'s objects here and stops,
  ``--slides FILE`` hands them to the estimator there (the same poses; ``benchmarks/device_pose.sh``).
* Peak memory: CPU: the process' peak resident set size (MiB); CUDA: ``torch.cuda.max_memory_allocated``.

The figures are also written as the result artifact ``results/pose_<profile>_<device>.json``
(``pose_<profile>_dense_<device>.json`` for ``--head dense``).
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from sixdpose.artifacts.results import add_result_arguments, save_from_args, script_command  # noqa: E402
from sixdpose.config import parse_overrides  # noqa: E402
from sixdpose.constants import SEG_BACKBONES  # noqa: E402
from sixdpose.datasets.base import Instance, Sample  # noqa: E402
from sixdpose.errors import ConfigError  # noqa: E402
from sixdpose.fileio import atomic_path  # noqa: E402
from sixdpose.options import Int  # noqa: E402
from sixdpose.pose import checkpoint as ck  # noqa: E402
from sixdpose.pose.config import APPEARANCES, profile_config, refiner_profile_config  # noqa: E402
from sixdpose.pose.dense import dense_loss  # noqa: E402
from sixdpose.pose.geometry import compose_refinement, to_object_frame  # noqa: E402
from sixdpose.pose.infer import Estimator  # noqa: E402
from sixdpose.pose.loss import pose_loss  # noqa: E402
from sixdpose.pose.model import build_posenet, build_refiner  # noqa: E402
from sixdpose.runs import save_checkpoint  # noqa: E402

K = np.array([[615.0, 0, 319.5], [0, 615.0, 239.5], [0, 0, 1]])


def peak_mib(device) -> float:
    """Peak memory so far (MiB): CUDA allocator peak, or the process' max RSS on CPU."""
    if device.type == "cuda":
        return torch.cuda.max_memory_allocated(device) / 2**20
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def synthetic_frame(n: int, seed: int = 0) -> Sample:
    """A 640x480 frame with ``n`` square masked objects (~90x90 px) on a depth plane at 0.6-0.9 m."""
    rng = np.random.default_rng(seed)
    H, W = 480, 640
    rgb = rng.integers(0, 255, (H, W, 3), dtype=np.uint8)
    depth = np.full((H, W), 0.9, np.float32)
    insts = []
    for k in range(n):
        v0, u0 = 40 + (k // 4) * 130, 20 + (k % 4) * 150
        m = np.zeros((H, W), bool)
        m[v0:v0 + 90, u0:u0 + 90] = True
        depth[m] = 0.6 + 0.02 * rng.random(m.sum())
        insts.append(Instance("obj", 1, k, np.eye(3), np.array([0, 0, 0.6]), m, int(m.sum())))
    return Sample(0, 0, rgb, depth, K, insts)


def fake_runs(profile: str, tmp: Path, classes: int = 21, head: str = "paper", appearance: str = "cnn",
              overrides: dict | None = None):
    """Untrained pose and refiner checkpoints of a profile (for timing only; no refiner for the dense head);
    ``overrides``: pose config fields replacing the profile's."""
    cfg = profile_config(profile, {"head": head, "appearance": appearance, **(overrides or {})})
    rcfg = refiner_profile_config(profile)
    cls = [[i + 1, f"obj{i + 1}", False] for i in range(classes)]
    torch.manual_seed(0)  # the same untrained weights every run
    net, ref = build_posenet(cfg, classes), build_refiner(rcfg, classes, cfg.emb_dim)
    pose = ck.weights("pose", cfg, cls, net.state_dict())
    save_checkpoint(pose, tmp / "pose.pt")
    save_checkpoint(ck.weights("refiner", rcfg, cls, ref.state_dict(), pose=ck.pose_link(pose, tmp / "pose.pt")),
                    tmp / "ref.pt")
    return tmp / "pose.pt", (tmp / "ref.pt" if head == "paper" else None)


def timed(fn, items, device) -> list[float]:
    """Wall seconds of ``fn(item)`` for each of ``items``, with the device synchronised around each call
    (CUDA kernels are asynchronous: without it the clock would stop before the work does)."""
    times = []
    for item in items:
        if device.type == "cuda":
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        fn(item)
        if device.type == "cuda":
            torch.cuda.synchronize()
        times.append(time.perf_counter() - t0)
    return times


def median_pass(fn, items, device, repeats: int) -> tuple[list[float], list[float]]:
    """Time ``repeats`` passes of ``fn`` over ``items`` (:func:`timed`). Returns the per-item times of the
    pass whose mean is the median (the lower middle for an even count: a shared machine's slow spells
    fall in single passes) and every pass' mean, seconds."""
    passes = [timed(fn, items, device) for _ in range(max(int(repeats), 1))]
    means = [float(np.mean(p)) for p in passes]
    return passes[median_index(means)], means


def median_index(means: list[float]) -> int:
    """The index of the median of ``means`` (the lower middle for an even count), as :func:`median_pass` picks."""
    return int(np.argsort(means)[(len(means) - 1) // 2])


def spread(means: list[float], key: str) -> dict:
    """The frame rates of the slowest and fastest passes (``<key>_fps_min``/``_max``) and the pass count."""
    return {f"{key}_fps_min": 1.0 / max(means), f"{key}_fps_max": 1.0 / min(means), f"{key}_passes": len(means)}


#: the fields of a trained run's config that shape its training step (benchmarks/pose.py --pose times its own)
STEP_FIELDS = ("head", "appearance", "width", "emb_dim", "crop", "norm", "translation", "rotation", "flips",
               "num_points", "num_model_points", "batch_size")


def train_throughput(profile: str, device, steps: int, inst_per_image: int = 6, classes: int = 21,
                     head: str = "paper", appearance: str = "cnn", overrides: dict | None = None) -> dict:
    """Instances per second of optimiser steps of the main network and of the refiner (paper head);
    ``overrides``: config fields replacing the profile's (a trained run's :data:`STEP_FIELDS`)."""
    cfg = profile_config(profile, {"head": head, "appearance": appearance, **(overrides or {})})
    rcfg = refiner_profile_config(profile)
    torch.manual_seed(0)
    net = build_posenet(cfg, classes).to(device).train()
    ref = build_refiner(rcfg, classes, cfg.emb_dim).to(device).train()
    opt, ropt = torch.optim.Adam(net.parameters(), 1e-4), torch.optim.Adam(ref.parameters(), 1e-4)
    n = cfg.batch_size * inst_per_image
    P, M = cfg.num_points, cfg.num_model_points
    side = (cfg.crop, cfg.crop) if cfg.crop else (480, 640)
    B = n if cfg.crop else cfg.batch_size
    imgs = torch.randn(B, 3, *side, device=device)
    img_index = torch.arange(n, device=device) if cfg.crop else torch.arange(n, device=device) // inst_per_image
    choose = torch.randint(0, side[0] * side[1], (n, P), device=device)
    cloud = torch.randn(n, P, 3, device=device) * 0.05 + torch.tensor([0, 0, 0.7], device=device)
    obj = torch.randint(0, classes, (n,), device=device)
    mp = torch.randn(n, M, 3, device=device) * 0.05
    R_gt, t_gt = torch.eye(3, device=device).expand(n, 3, 3), cloud.mean(1)
    sym = torch.zeros(n, dtype=torch.bool, device=device)
    amp = device.type == "cuda"

    targets = torch.randn(n, 1, P, 3, device=device) * 0.05

    def step_main():
        with torch.autocast("cuda", dtype=torch.float16, enabled=amp):
            out = net(imgs, img_index, choose, cloud, obj)
        if head == "dense":
            loss = dense_loss(out["coords"].float(), out["conf_logit"].float(), targets)[0].mean()
        else:
            loss = pose_loss(out["R"].float(), out["t"].float(), R_gt, t_gt, mp, sym).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()

    def step_ref():
        with torch.no_grad(), torch.autocast("cuda", dtype=torch.float16, enabled=amp):
            out = net(imgs, img_index, choose, cloud, obj)
        R, t, emb = out["R"].float(), out["t"].float(), out["emb"].float()
        for _ in range(rcfg.iterations):
            R_r, t_r = ref(to_object_frame(cloud, R, t), emb, obj)
            R, t = compose_refinement(R, t, R_r, t_r)
        loss = pose_loss(R, t, R_gt, t_gt, mp, sym).mean()
        ropt.zero_grad()
        loss.backward()
        ropt.step()

    res = {}
    for name, fn in (("pose", step_main), ("refiner", step_ref))[: 1 if head == "dense" else 2]:
        for _ in range(2):
            fn()
        res[f"train_{name}_instances_per_s"] = n * steps / sum(timed(lambda _, f=fn: f(), range(steps), device))
    res["train_instances_per_step"] = n
    return res


def load_slides(path: str | None) -> dict[int, np.ndarray]:
    """The colour-named slides saved by ``--save-slides`` (obj_id -> (S, 4, 4)), or {} without a path.
    Raises ValueError (one line naming the file) for a missing or unreadable file or a key not ``obj_<id>``."""
    if not path:
        return {}
    try:
        with np.load(path) as z:
            return {int(k.removeprefix("obj_")): np.asarray(z[k], float).reshape(-1, 4, 4) for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile) as e:
        raise ValueError(f"{path}: not slides written by --save-slides ({str(e).splitlines()[0][:200]})") from None


def save_slides(path: str, slides: dict[int, np.ndarray]) -> None:
    """Write ``slides`` (obj_id -> (S, 4, 4)) to the .npz ``path`` atomically (:func:`load_slides` reads it)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:  # a file object: np.savez adds no suffix
        np.savez(f, **{f"obj_{o}": S for o, S in slides.items()})


def set_up(est: Estimator, slides: dict | None, amp: bool | None) -> Estimator:
    """``est`` with colour-named slides built elsewhere (:func:`load_slides`) and, unless None, its precision
    on a GPU (:attr:`Estimator.amp`)."""
    est.preload_slides(slides or {})
    if amp is not None:
        est.amp = amp
    return est


def inference_fps(pose, refiner, device, instances: int, frames: int, data: str | None = None,
                  repeats: int = 1, slides: dict | None = None, amp: bool | None = None) -> dict:
    """Frames per second of Estimator.predict (pose net + 2 refinement iterations, or the dense head's robust
    fit when ``refiner`` is None) on a synthetic frame of ``instances`` objects, or with ``data`` (``PATH`` or
    ``PATH@SPLIT``) on its first ``frames`` frames with their ground-truth masks, the reader given to the
    estimator (so a run naming its flips by the models' colours does so; disk reads not timed). ``slides``:
    colour-named slides built elsewhere (:func:`load_slides`), for a machine without Open3D. ``amp``: half
    precision on a GPU (:attr:`Estimator.amp`; None: the estimator's default)."""
    if data is None:
        est = set_up(Estimator(pose, refiner, iterations=2 if refiner else 0, device=str(device)), None, amp)
        samples = [synthetic_frame(instances)] * (frames + 1)
    else:
        from sixdpose.datasets import as_reader

        path, _, split = data.partition("@")
        reader = as_reader(path, split=split or "test")
        samples = [reader.load(k) for k in reader.keys()[: frames + 1]]
        est = set_up(Estimator(pose, refiner, iterations=2 if refiner else 0, device=str(device), reader=reader),
                     slides, amp)
    for s in samples if data is not None else samples[:1]:  # warm-up: first-call allocations, and with
        est.predict(s)  # --data each object's onboarding (model reads, model-side data), not timed
    times, means = median_pass(lambda s: est.predict(s), samples[1:], device, repeats)
    n_inst = float(np.mean([len(s.instances) for s in samples[1:]]))
    return {"infer_fps": 1.0 / float(np.mean(times)), "infer_ms_per_frame": 1000 * float(np.mean(times)),
            "infer_instances_per_frame": n_inst, **(spread(means, "infer") if repeats > 1 else {})}


def untrained_seg(profile: str, pose, tmp: Path, backbone: str | None = None) -> Path:
    """An untrained Mask R-CNN checkpoint of segmentation profile ``profile`` (its ``backbone`` replaced when
    given, as ``SEG_FAST_cpu`` in mk/profiles.mk does) with the pose run's classes (for timing only:
    :func:`end_to_end_fps` with ``untrained=True``)."""
    from sixdpose.segmentation import checkpoint as seg_ck
    from sixdpose.segmentation.config import profile_config as seg_profile_config
    from sixdpose.segmentation.model import build_model

    cfg = seg_profile_config(profile, pretrained=False, **({"backbone": backbone} if backbone else {}))
    classes = [[int(c[0]), str(c[1])] for c in ck.load(pose, kind="pose")["classes"]]
    torch.manual_seed(0)  # the same untrained weights every run
    model, init = build_model(cfg, len(classes), verbose=False)
    save_checkpoint(seg_ck.weights(cfg, classes, init, model.state_dict()), tmp / "seg.pt")
    return tmp / "seg.pt"


def end_to_end_fps(seg, pose, refiner, data, device, frames: int, untrained: bool = False,
                   compile_seg: bool | None = None, repeats: int = 1, slides: dict | None = None,
                   amp: bool | None = None, seg_overrides: dict | None = None) -> dict:
    """Frames per second of segmentation + pose + 2 refinement iterations on a dataset's first frames, and the
    two parts' milliseconds per frame (``e2e_seg_ms_per_frame``: Mask R-CNN and its detections;
    ``e2e_pose_ms_per_frame``: the pose stage on them) in the reported pass.

    ``compile_seg``: the Segmenter's ``optimise`` (None: its default, compiled on the CPU). ``repeats``:
    timed passes over the frames; the median pass is reported (:func:`median_pass`). ``slides``: as
    :func:`inference_fps`. ``amp``: as :func:`inference_fps`. ``seg_overrides``: the Segmenter's inference
    fields to change (``--seg-set``, e.g. ``amp=false``).

    ``untrained``: ``seg`` is an untrained network (:func:`untrained_seg`): it is made to return as many
    detections as each frame has objects, and the pose stage runs on the ground-truth masks."""
    from sixdpose.artifacts.predictions import Detection
    from sixdpose.datasets import as_reader
    from sixdpose.segmentation.infer import Segmenter

    path, _, split = data.partition("@")
    reader = as_reader(path, split=split or "test")
    samples = [reader.load(k, masks=untrained) for k in reader.keys()[: frames + 1]]  # disk reads not timed
    # scores >= 0.5, as predict-pose; the reader for flips named by colour
    est = set_up(Estimator(pose, refiner, iterations=2 if refiner else 0, device=str(device), reader=reader),
                 slides, amp)
    split: list[tuple[float, float]] = []  # (segmentation, pose stage) seconds of every call

    def both(segment, pose):
        """Run ``segment()``, then ``pose(its output)``, recording the two times (both return host arrays,
        so a GPU has finished each part when its clock stops)."""
        t0 = time.perf_counter()
        out = segment()
        t1 = time.perf_counter()
        rows = pose(out)
        split.append((t1 - t0, time.perf_counter() - t1))
        return rows

    if untrained:  # one network per detection count, each returning exactly that many
        segms = {n: Segmenter(seg, device=str(device), score_thresh=0.0,
                              overrides={**(seg_overrides or {}), "detections_per_img": n},
                              optimise=compile_seg)
                 for n in {max(len(s.instances), 1) for s in samples}}

        def run(sample):
            return both(lambda: segms[max(len(sample.instances), 1)].predict([sample.rgb])[0],
                        lambda out: (est.predict(sample), len(out["labels"])))
    else:  # detections below the pose stage's score are dropped before their masks are pasted: the estimator
        # ignores them anyway, and a box kept by the score floor is never suppressed by a lower-scored one
        segm = Segmenter(seg, device=str(device), score_thresh=est.score_thresh, optimise=compile_seg,
                         overrides=seg_overrides)

        def detections(out):
            return [Detection(int(o), float(s), m)
                    for o, s, m in zip(out["labels"], out["scores"], out["masks"], strict=True)]

        def run(sample):
            return both(lambda: detections(segm.predict([sample.rgb])[0]),
                        lambda dets: (est.predict(sample, dets), len(dets)))

    for s in samples:  # warm-up: first-call allocations and each object's onboarding, not timed
        run(s)
    split.clear()
    n_det = []
    times, means = median_pass(lambda s: n_det.append(run(s)[1]), samples[1:], device, repeats)
    n = len(times)
    parts = np.asarray(split[median_index(means) * n:(median_index(means) + 1) * n])  # the reported pass'
    res = {"e2e_fps": 1.0 / float(np.mean(times)), "e2e_ms_per_frame": 1000 * float(np.mean(times)),
           "e2e_seg_ms_per_frame": 1000 * float(parts[:, 0].mean()),
           "e2e_pose_ms_per_frame": 1000 * float(parts[:, 1].mean()),
           "e2e_detections_per_frame": sum(n_det) / max(len(n_det), 1), "e2e_frames": len(times),
           **(spread(means, "e2e") if repeats > 1 else {})}
    if untrained:
        res["e2e_segmentation"] = "untrained, detections fixed to the frame's objects; pose on GT masks"
    else:
        res["e2e_segmentation"] = (f"{segm.cfg.backbone}{' (compiled for the CPU)' if segm.optimised else ''}, "
                                   f"detections scoring >= {est.score_thresh:g}")
    return res


def main(argv=None) -> int:
    """Parse the arguments, run the benchmarks, print (and optionally save) the figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", default="cpu", choices=("smoke", "cpu", "paper"))
    ap.add_argument("--head", default="paper", choices=("paper", "dense"),
                    help="the untrained networks' head (without --pose)")
    ap.add_argument("--appearance", default="cnn", choices=APPEARANCES,
                    help="the untrained networks' per-point embedding (dense head; without --pose)")
    ap.add_argument("--pose", default=None, help="a trained pose run (default: untrained networks of --profile)")
    ap.add_argument("--refiner", default=None, help="a trained refiner run (with --pose)")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--instances", type=int, default=6, help="objects per frame (inference) and per image (training)")
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--repeats", type=Int(1, 1000), default=1,
                    help="timed passes over the frames; the median pass is reported, with the slowest and "
                         "fastest (a shared machine's slow spells fall in single passes)")
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--json", default=None)
    ap.add_argument("--seg", default=None, help="a trained segmentation run: also time segmentation + pose end to end")
    ap.add_argument("--seg-eager", action="store_true",
                    help="run Mask R-CNN's backbone eagerly (default on the CPU: compiled, the same detections)")
    ap.add_argument("--seg-profile", default=None, choices=("smoke", "cpu", "paper"),
                    help="time end to end with an untrained Mask R-CNN of this segmentation profile instead of "
                         "--seg (detections fixed to the frame's objects, pose on GT masks)")
    ap.add_argument("--seg-backbone", default=None, choices=sorted(SEG_BACKBONES),
                    help="with --seg-profile: that profile's Mask R-CNN with this backbone instead (e.g. "
                         "mobilenet_v3_large, the cpu graph's real-time segmenter)")
    ap.add_argument("--seg-set", action="append", default=[], metavar="FIELD=VALUE",
                    help="an inference field of the Mask R-CNN to change (repeatable; e.g. amp=false)")
    ap.add_argument("--data", default=None,
                    help="PATH[@SPLIT]: time inference on its first --frames frames (GT masks; with --seg, end to "
                         "end on the segmentation's masks as well) instead of a synthetic frame")
    ap.add_argument("--slides", default=None,
                    help="an .npz of the colour-named slides (from --save-slides on a machine with Open3D): used "
                         "instead of building them, so a machine without Open3D runs the same poses")
    ap.add_argument("--amp", action=argparse.BooleanOptionalAction, default=None,
                    help="the pose networks in half precision (autocast) on a GPU, or with --no-amp in float32; "
                         "default: the estimator's (Estimator.amp: half for the paper head, float32 for the dense)")
    ap.add_argument("--fp32", dest="amp", action="store_false", help="the same as --no-amp")
    ap.add_argument("--save-slides", default=None,
                    help="write the colour-named slides of --data's objects (first --frames + 1 frames) to this "
                         ".npz and stop (needs Open3D)")
    add_result_arguments(ap, None, Path(__file__).resolve().parents[1] / "results", "pose_<profile>_<device>")
    a = ap.parse_args(argv)
    if a.seg and a.seg_profile:
        print("--seg and --seg-profile exclude each other", file=sys.stderr)
        return 2
    if a.seg_backbone and not a.seg_profile:
        print("--seg-backbone needs --seg-profile", file=sys.stderr)
        return 2
    seg_any = a.seg or a.seg_profile
    if (seg_any and a.data is None) or (seg_any and not a.pose) or (a.data and not a.pose):
        print("--seg/--seg-profile need --data, and both need --pose (and --refiner)", file=sys.stderr)
        return 2
    if a.appearance != "cnn" and a.head != "dense":
        print("--appearance other than cnn needs --head dense", file=sys.stderr)
        return 2
    if a.threads:
        torch.set_num_threads(a.threads)
    device = torch.device(a.device)
    if device.type == "cuda" and not torch.cuda.is_available():
        print("CUDA is not available", file=sys.stderr)
        return 2
    if a.save_slides:
        if not (a.pose and a.data):
            print("--save-slides needs --pose and --data", file=sys.stderr)
            return 2
        from sixdpose.datasets import as_reader

        path, _, split = a.data.partition("@")
        reader = as_reader(path, split=split or "test")
        objs = sorted({g.obj_id for k in reader.keys()[: a.frames + 1]
                       for g in reader.load(k, masks=False, rgb=False, depth=False).instances})
        est = Estimator(a.pose, None, iterations=0, device="cpu", reader=reader)
        slides = est.export_slides(o for o in objs if o in est.class_index)
        save_slides(a.save_slides, slides)
        print(f"slides of objects {sorted(slides)} ({sum(len(S) for S in slides.values())} in all) -> {a.save_slides}")
        return 0
    try:
        slides = load_slides(a.slides)
    except ValueError as e:
        print(f"--slides: {e}", file=sys.stderr)
        return 2
    from sixdpose.segmentation.infer import check_inference_overrides

    try:
        seg_set = check_inference_overrides(parse_overrides(a.seg_set))
    except ConfigError as e:
        print(f"--seg-set: {e}", file=sys.stderr)
        return 2
    head, appearance, step_cfg = a.head, a.appearance, {}
    if a.pose:  # a trained run: its own head, embedding and network (for the training step timed too)
        saved = ck.load(a.pose, kind="pose")["config"]
        head, appearance = saved.get("head", "paper"), saved.get("appearance", "cnn")
        step_cfg = {k: saved[k] for k in STEP_FIELDS if k in saved}
    if a.result_name is None:
        look = "" if appearance == "cnn" else f"{appearance}_"
        a.result_name = f"pose_{a.profile}_{'dense_' if head == 'dense' else ''}{look}{device.type}"
    out = {"profile": a.profile, "head": head, "appearance": appearance, "device": str(device),
           "threads": torch.get_num_threads()}
    with tempfile.TemporaryDirectory() as tmp:
        pose, ref = (a.pose, a.refiner) if a.pose else fake_runs(a.profile, Path(tmp), head=head, appearance=appearance)
        out.update(inference_fps(pose, ref, device, a.instances, a.frames, a.data, a.repeats, slides, a.amp))
        out["infer_peak_mib"] = peak_mib(device)
        if a.seg:
            out.update(end_to_end_fps(a.seg, pose, ref, a.data, device, a.frames,
                                      compile_seg=False if a.seg_eager else None, repeats=a.repeats,
                                      slides=slides, amp=a.amp, seg_overrides=seg_set))
        elif a.seg_profile:
            seg = untrained_seg(a.seg_profile, pose, Path(tmp), a.seg_backbone)
            out.update(end_to_end_fps(seg, pose, ref, a.data, device, a.frames, untrained=True,
                                      compile_seg=False if a.seg_eager else None, repeats=a.repeats,
                                      slides=slides, amp=a.amp, seg_overrides=seg_set))
        if device.type == "cuda":
            torch.cuda.reset_peak_memory_stats(device)
        out.update(train_throughput(a.profile, device, a.steps, a.instances, head=head, appearance=appearance,
                                    overrides=step_cfg))
        out["train_peak_mib"] = peak_mib(device)
    for k, v in out.items():
        print(f"{k:32s} {v:.2f}" if isinstance(v, float) else f"{k:32s} {v}")
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1) + "\n")
    suffix_units = {"instances_per_s": "instances/s", "_fps": "frames/s", "_fps_min": "frames/s",
                    "_fps_max": "frames/s", "_ms_per_frame": "ms", "_mib": "MiB"}
    units = {k: u for k in out for end, u in suffix_units.items() if k.endswith(end)}
    nets = "trained runs" if a.pose else f"untrained {a.profile} networks"
    save_from_args(a, out, command=script_command(__file__, argv), units=units,
                   description=f"learned pose stage ({nets}) "
                               f"on {out['device']}: inference FPS with {out['infer_instances_per_frame']:g} "
                               "instances per frame "
                               + ("(+ 2 refinement iterations)" if head == "paper"
                                  else f"(dense head, {appearance} embedding, RANSAC fit)")
                               + (f" on {a.data} (GT masks)" if a.data else "")
                               + ", training instances/s, peak memory"
                               + ("; end to end with segmentation on " + Path(a.data).name if a.seg else "")
                               + (f"; end to end with an untrained {a.seg_profile} Mask R-CNN"
                                  + (f" ({a.seg_backbone})" if a.seg_backbone else "") + " (detections fixed "
                                  "to the frame's objects, pose on GT masks) on " + Path(a.data).name
                                  if a.seg_profile else ""),
                   config={"profile": a.profile, "head": head, "appearance": appearance, "pose": a.pose,
                           "refiner": a.refiner,
                           "device": a.device, "instances": a.instances, "frames": a.frames, "repeats": a.repeats,
                           "steps": a.steps,
                           "threads": a.threads, "slides": a.slides, "amp": a.amp, "seg": a.seg,
                           "seg_profile": a.seg_profile,
                           "seg_backbone": a.seg_backbone, "seg_set": seg_set, "data": a.data,
                           "pose_config": profile_config(a.profile, {"head": head, "appearance": appearance}).to_dict()
                           if not a.pose else None})
    return 0


if __name__ == "__main__":
    sys.exit(main())
