"""Training loops of the learned stage: the main network (``train_pose``) and the refiner
(``train_refiner``); single process, or DDP under ``torchrun`` (NCCL on GPUs, gloo on CPU).

Run directory after training::

    config.json   the PoseConfig / RefinerConfig of the run
    run.json      classes, world size, device, versions, data (and the pose run for a refiner)
    metrics.csv   one row per logged step (epoch, step, lr, loss in metres, seconds) and one per epoch
                  with ``val_add`` (ADD(-S) accuracy in % on ``--val``, GT masks) when a validation set is given
    last.pt       resumable checkpoint, rewritten atomically after every epoch (see :mod:`.checkpoint`)
    model.pt      final weights, written when the epochs are done or the time budget is spent

Learning rate at step ``s`` of epoch ``e``: ``lr * lr_gamma ** (e // lr_step_epochs) * w(s)`` with the
exponential warm-up ``w(s) = 1000 ** (s / warmup_steps - 1)`` for ``s < warmup_steps`` (then 1), i.e.
a per-epoch StepLR times a per-step warm-up. Randomness (shuffling, point and model-point sampling,
RGB noise, refiner noise) is drawn from generators seeded by (seed, epoch, step/item, rank), so a
resumed run repeats exactly what an uninterrupted one does (the RNG states are saved as well).
"""

from __future__ import annotations

import csv
import logging
import math
import platform
import time
from contextlib import nullcontext
from pathlib import Path

import numpy as np
import torch
import torch.distributed as dist

from ..datasets.base import as_reader
from ..errors import SixdposeError
from ..fileio import atomic_write_json, claim_output_dir
from ..runs import append_metrics, process_group, rng_state, save_checkpoint, set_rng_state, truncate_metrics
from . import checkpoint as ck
from .config import PoseConfig, RefinerConfig, profile_config, refiner_profile_config
from .data import FrameDataset, PoseError, collate_frames, collate_list, sample_model_points
from .geometry import compose_refinement, perturb_poses, to_object_frame
from .loss import pose_loss
from .model import build_posenet, build_refiner

log = logging.getLogger("sixdpose.pose")
CSV_FIELDS = ("epoch", "step", "lr", "loss", "val_add", "seconds")
RESUMABLE = ("epochs", "num_threads", "num_workers", "time_budget", "log_every")


class TrainingError(SixdposeError):
    """Training cannot start or continue (bad run directory, diverged loss, ...)."""


def learning_rate(cfg, epoch: int, step: int) -> float:
    """Learning rate of global ``step`` in ``epoch`` (see the module docstring)."""
    lr = cfg.lr * cfg.lr_gamma ** (epoch // cfg.lr_step_epochs)
    if cfg.warmup_steps and step < cfg.warmup_steps:
        lr *= 1000.0 ** (step / cfg.warmup_steps - 1.0)
    return lr


def _prepare_run_dir(run_dir: Path, resume: bool, cls, profile_fn, profile, overrides: dict, kind: str):
    cfg_path = run_dir / "config.json"
    if resume:
        if not cfg_path.is_file():
            raise TrainingError(f"{run_dir}: nothing to resume (no config.json); start a new run without --resume")
        saved = cls.load(cfg_path)
        if profile and profile != saved.profile:
            raise TrainingError(f"{run_dir}: the run was started with profile {saved.profile!r}, not {profile!r}")
        bad = sorted(k for k, v in overrides.items() if k not in RESUMABLE and getattr(saved, k, None) != v)
        if bad:
            raise TrainingError(f"cannot change {', '.join(bad)} when resuming (only {', '.join(RESUMABLE)})")
        return saved.replace(**{k: v for k, v in overrides.items() if k in RESUMABLE})
    if (run_dir / ck.LAST).exists() or (run_dir / ck.FINAL).exists() or cfg_path.exists():
        raise TrainingError(f"{run_dir}: already holds a run; use --resume to continue it or choose another --out")
    claim_output_dir(run_dir, kind)
    return profile_fn(profile or "smoke", overrides)


def read_metrics(run_dir: str | Path) -> list[dict]:
    """The rows of ``RUN/metrics.csv`` (numbers parsed; empty cells are None)."""
    path = Path(run_dir) / "metrics.csv"
    if not path.is_file():
        raise TrainingError(f"{path}: no metrics (training has not completed an epoch)")
    with open(path, newline="") as f:
        return [{k: (None if v == "" else int(v) if k in ("epoch", "step") else float(v)) for k, v in r.items()}
                for r in csv.DictReader(f)]


def dataset_classes(reader) -> list[list]:
    """``[[obj_id, name, symmetric], ...]`` of every model of a dataset, sorted by id."""
    return [[int(oid), str(name), bool(reader.model(oid).symmetric)] for oid, name in sorted(reader.object_ids.items())]


def validate_accuracy(reader, posenet, cfg, classes, device, refiner=None, iterations: int = 0, limit: int = 0) -> float:
    """ADD(-S) accuracy (%) of the networks on a reader's GT-mask instances (the paper's 10 % criterion)."""
    from ..evaluation.evaluate import evaluate
    from .infer import Estimator

    est = Estimator.from_networks(posenet, cfg, classes, refiner, iterations=iterations if refiner is not None else 0,
                                  device=device, reader=reader, score_thresh=0.0)
    was = [posenet.training] + ([refiner.training] if refiner is not None else [])
    posenet.eval()
    if refiner is not None:
        refiner.eval()
    rows = []
    keys = reader.keys()[:limit] if limit else reader.keys()
    for key in keys:
        rows.extend(est.predict(reader.load(key)))
    posenet.train(was[0])
    if refiner is not None:
        refiner.train(was[1])
    return float(evaluate(reader, rows, min_px=0, images=keys).accuracy)


def train_pose(data, run_dir, *, profile: str | None = None, resume: bool = False, masks: str = "gt", val=None,
               device: str | None = None, progress: bool = True, **overrides) -> dict:
    """Train the main pose network and write the run directory (see the module docstring).

    Args:
        data: training dataset (reader or path). run_dir: output run directory.
        profile: ``smoke`` | ``cpu`` | ``paper`` (default smoke; on resume the run's own).
        resume: continue the run in ``run_dir`` (``epochs``, ``time_budget``, threads/workers may change).
        masks: ``"gt"`` or a prediction directory (predicted masks matched to GT by IoU >= 0.5).
        val: optional validation dataset (reader or path) scored every epoch into metrics.csv.
        device: cpu/cuda/auto. progress: progress bars. **overrides: PoseConfig fields.
    Returns:
        summary dict (run_dir, epochs done, start_epoch, steps, first_loss/last_loss (m), val_add,
        stopped_early, seconds).
    """
    return _run("pose", data, run_dir, profile=profile, resume=resume, masks=masks, val=val, device=device,
                progress=progress, overrides=overrides, pose_run=None)


def train_refiner(pose_run, data, run_dir, *, profile: str | None = None, resume: bool = False, val=None,
                  device: str | None = None, progress: bool = True, **overrides) -> dict:
    """Train the iterative refiner on a finished main network's (noised) poses.

    Args:
        pose_run: run directory (or checkpoint) of :func:`train_pose`. Other arguments as
            :func:`train_pose` (ground-truth masks; RefinerConfig fields as overrides).
    Raises:
        CheckpointError: the pose run is corrupt, or on resume differs (classes/architecture) from the
            one the refiner was started on.
    """
    return _run("refiner", data, run_dir, profile=profile, resume=resume, masks="gt", val=val, device=device,
                progress=progress, overrides=overrides, pose_run=pose_run)


def _run(kind, data, run_dir, *, profile, resume, masks, val, device, progress, overrides, pose_run) -> dict:
    with process_group(device) as (dev, world, rank):
        return _train(kind, data, Path(run_dir), profile, resume, masks, val, dev, progress, overrides, pose_run, world, rank)


def _train(kind, data, run_dir, profile, resume, masks, val, dev, progress, overrides, pose_run, world, rank) -> dict:
    t_start = time.time()
    distributed = world > 1
    is_pose = kind == "pose"
    cls, pfn = (PoseConfig, profile_config) if is_pose else (RefinerConfig, refiner_profile_config)
    command = "train-pose" if is_pose else "train-refiner"
    claim_output_dir(run_dir, command, create=False)  # refuse a foreign directory before reading anything
    reader = as_reader(data, split="train")
    if masks != "gt" and not Path(masks).is_dir():
        raise PoseError(f"{masks}: prediction directory not found (use --masks gt for ground-truth masks)")
    if masks != "gt":
        from ..artifacts.predictions import check_predictions_dataset

        check_predictions_dataset(masks, reader)  # masks of another dataset are refused
    pose_ckpt = posenet = None
    if not is_pose:
        pose_ckpt = ck.load(pose_run, kind="pose")
    # rank 0 checks/claims the directory; then every rank reads the saved config
    if rank == 0:
        cfg = _prepare_run_dir(run_dir, resume, cls, pfn, profile, overrides, command)
        cfg.save(run_dir / "config.json")
    if distributed:
        dist.barrier()
    cfg = cls.load(run_dir / "config.json")
    if cfg.num_threads > 0:
        torch.set_num_threads(cfg.num_threads)
    last = ck.load(run_dir / ck.LAST, kind=kind) if resume and (run_dir / ck.LAST).exists() else None

    if is_pose:
        classes = dataset_classes(reader)
        arch = cfg.arch()
        crop, margin = cfg.crop, cfg.crop_margin
    else:
        classes = [list(c) for c in pose_ckpt["classes"]]
        arch = cfg.arch()
        from .infer import load_posenet

        posenet, pose_cfg = load_posenet(pose_ckpt, dev)
        for p in posenet.parameters():
            p.requires_grad_(False)
        crop, margin = pose_cfg.crop, pose_cfg.crop_margin
        if last is not None:
            try:
                ck.check_refiner_matches(last, pose_ckpt)
            except ck.CheckpointError as e:
                raise ck.CheckpointError(f"--pose {pose_ckpt['path']} does not match the run being resumed: {e}") from None
    if last is not None and [list(c) for c in last["classes"]] != classes:
        raise ck.CheckpointError(f"{last['path']}: the run was trained on other object classes than {reader.location} has")
    class_index = {int(c[0]): k for k, c in enumerate(classes)}
    sym = {int(c[0]): bool(c[2]) for c in classes}
    present = set(reader.object_ids)
    if not present & set(class_index):
        raise PoseError(f"{reader.location}: none of its objects is a class of the pose run")
    model_points = {oid: reader.model(oid).points.astype(np.float32) for oid in class_index if oid in present}

    torch.manual_seed(cfg.seed)  # identical initialisation on every rank
    if is_pose:
        net = build_posenet(cfg, len(classes))
        centres = np.zeros((len(classes), 3), np.float32)
        for oid, pts in model_points.items():
            centres[class_index[oid]] = (pts.min(0) + pts.max(0)) / 2.0
        net.set_centres(centres)
    else:
        net = build_refiner(cfg, len(classes), int(pose_ckpt["arch"]["emb_dim"]))
    net.to(dev)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    use_amp = cfg.amp and dev.type == "cuda"
    scaler = torch.amp.GradScaler("cuda", enabled=use_amp)
    start_epoch, global_step, elapsed = 0, 0, 0.0
    if last is not None:
        try:
            net.load_state_dict(last["model"])
            opt.load_state_dict(last["optimizer"])
            if use_amp and "scaler" in last:
                scaler.load_state_dict(last["scaler"])
        except (RuntimeError, KeyError, ValueError) as e:
            raise ck.CheckpointError(f"{last['path']}: incompatible with the run's config ({str(e).splitlines()[0][:200]})") from None
        start_epoch, global_step, elapsed = int(last["epoch"]), int(last.get("global_step", 0)), float(last.get("elapsed", 0.0))
        states = last.get("rng") or []
        if last.get("world_size") == world and len(states) == world:
            set_rng_state(states[rank])
        if rank == 0:
            log.warning("resuming %s at epoch %d of %d", run_dir, start_epoch + 1, cfg.epochs)
    val_reader = as_reader(val, split="test") if val is not None else None
    if rank == 0:
        truncate_metrics(run_dir / "metrics.csv", start_epoch, CSV_FIELDS)
        info = {"kind": kind, "classes": classes, "world_size": world, "device": str(dev), "amp": use_amp,
                "torch": torch.__version__, "python": platform.python_version(), "data": str(reader.location), "masks": masks}
        if pose_ckpt is not None:
            info["pose_run"] = pose_ckpt["path"]
        atomic_write_json(run_dir / "run.json", info)

    train_net = net
    if distributed:
        train_net = torch.nn.parallel.DistributedDataParallel(net, device_ids=[dev.index] if dev.type == "cuda" else None)
    keys = reader.keys()[: cfg.max_images] if cfg.max_images else reader.keys()
    keys = list(keys) * cfg.repeat
    ds = FrameDataset(reader, keys, cfg, class_index, crop, margin, masks=masks, seed=cfg.seed)
    per_rank = math.ceil(len(ds) / world)
    steps_per_epoch = math.ceil(per_rank / cfg.batch_size)

    def payload(epoch, final: bool, states=None) -> dict:
        d = {"format": ck.FORMAT, "version": ck.CHECKPOINT_VERSION, "kind": kind, "config": cfg.to_dict(), "arch": arch,
             "classes": classes, "epoch": epoch, "global_step": global_step, "elapsed": elapsed, "model": net.state_dict()}
        if not is_pose:
            d["pose"] = {"classes": pose_ckpt["classes"], "arch": pose_ckpt["arch"], "run": pose_ckpt["path"]}
        if not final:
            d.update(optimizer=opt.state_dict(), scaler=scaler.state_dict(), rng=states, world_size=world)
        return d

    epoch_means, steps_run, val_add, stopped_early = [], 0, None, False
    epoch = start_epoch
    for epoch in range(start_epoch, cfg.epochs):
        t_epoch = time.time()
        ds.set_epoch(epoch)
        order = np.random.default_rng([cfg.seed, epoch, 7]).permutation(len(ds))
        if len(order) % world:
            order = np.concatenate([order, order[: world - len(order) % world]])
        loader = torch.utils.data.DataLoader(ds, batch_size=cfg.batch_size, sampler=order[rank::world].tolist(),
                                             num_workers=cfg.num_workers, collate_fn=collate_list)
        train_net.train()
        bar = None
        if progress and rank == 0:
            from tqdm.auto import tqdm

            bar = tqdm(total=steps_per_epoch, desc=f"{kind} epoch {epoch + 1}/{cfg.epochs}", leave=False, dynamic_ncols=True)
        rows, losses = [], []
        for step, frames in enumerate(loader):
            rng = np.random.default_rng([cfg.seed, epoch, step, rank, 11])
            batch = collate_frames(frames, class_index, cfg.rgb_noise if is_pose else 0.0, rng,
                                   cfg.colour_jitter if is_pose else 0.0)
            insts = batch["instances"]
            if not insts:
                if distributed:
                    raise TrainingError(f"a batch without usable instances at epoch {epoch + 1} step {step + 1} (under DDP every "
                                        "step needs instances: drop images without objects)")
                continue
            lr = learning_rate(cfg, epoch, global_step)
            for g in opt.param_groups:
                g["lr"] = lr
            mp = sample_model_points(model_points, [i.obj_id for i in insts], cfg.num_model_points, rng).to(dev)
            symm = torch.tensor([sym[i.obj_id] for i in insts], device=dev)
            R_gt, t_gt = batch["R"].to(dev), batch["t"].to(dev)
            cloud, obj = batch["cloud"].to(dev), batch["obj_index"].to(dev)
            with torch.autocast("cuda", dtype=torch.float16) if use_amp else nullcontext():
                if is_pose:
                    out = train_net(batch["images"].to(dev), batch["img_index"].to(dev), batch["choose"].to(dev), cloud, obj)
                    R, t = out["R"].float(), out["t"].float()
                else:
                    with torch.no_grad():
                        out = posenet(batch["images"].to(dev), batch["img_index"].to(dev), batch["choose"].to(dev), cloud, obj)
                    Rn, tn = perturb_poses(out["R"].float().cpu().double().numpy(), out["t"].float().cpu().double().numpy(),
                                           cfg.noise_rot_deg, cfg.noise_trans, rng)
                    R = torch.from_numpy(Rn).float().to(dev)
                    t = torch.from_numpy(tn).float().to(dev)
                    emb = out["emb"].float().detach()
                    for _ in range(cfg.iterations):
                        R_r, t_r = train_net(to_object_frame(cloud, R, t), emb, obj)
                        R, t = compose_refinement(R, t, R_r.float(), t_r.float())
            loss = pose_loss(R.float(), t.float(), R_gt, t_gt, mp, symm).mean()
            if not torch.isfinite(loss):
                raise TrainingError(f"loss became {loss.item()} at epoch {epoch + 1} step {step + 1}; training diverged (lower lr?)")
            opt.zero_grad(set_to_none=True)
            scaler.scale(loss).backward()
            if cfg.grad_clip > 0:
                scaler.unscale_(opt)
                torch.nn.utils.clip_grad_norm_(net.parameters(), cfg.grad_clip)
            scaler.step(opt)
            scaler.update()
            lv = loss.detach().float()
            if distributed:
                dist.all_reduce(lv)
                lv /= world
            lv = float(lv)
            losses.append(lv)
            global_step += 1
            steps_run += 1
            spent = False
            if cfg.time_budget > 0:  # checked after every step: a long epoch cannot overrun the budget
                flag = torch.tensor([float(elapsed + time.time() - t_epoch >= cfg.time_budget)])
                if distributed:
                    dist.broadcast(flag, 0)
                spent = bool(flag.item())
            if rank == 0 and (step % cfg.log_every == 0 or step == steps_per_epoch - 1 or spent):
                rows.append({"epoch": epoch, "step": global_step, "lr": f"{lr:.6g}", "loss": round(lv, 6), "val_add": "",
                             "seconds": round(time.time() - t_start, 3)})
            if bar is not None:
                bar.set_postfix(loss=f"{lv:.4f}")
                bar.update(1)
            if spent:
                if rank == 0 and step + 1 < steps_per_epoch:
                    log.warning("time budget of %.0f s spent at step %d of %d of epoch %d: the rest of the epoch is skipped",
                                cfg.time_budget, step + 1, steps_per_epoch, epoch + 1)
                break
        if bar is not None:
            bar.close()
        mean = float(np.mean(losses)) if losses else math.nan
        epoch_means.append(mean)
        elapsed += time.time() - t_epoch
        if rank == 0 and val_reader is not None:
            if is_pose:
                val_add = validate_accuracy(val_reader, net, cfg, classes, dev)
            else:
                val_add = validate_accuracy(val_reader, posenet, pose_cfg, classes, dev, refiner=net, iterations=cfg.iterations)
            rows.append({"epoch": epoch, "step": global_step, "lr": f"{lr if losses else 0:.6g}", "loss": round(mean, 6),
                         "val_add": round(val_add, 3), "seconds": round(time.time() - t_start, 3)})
        states = [rng_state()]
        if distributed:
            gathered = [None] * world
            dist.all_gather_object(gathered, states[0])
            states = gathered
        stop = torch.tensor([float(cfg.time_budget > 0 and elapsed >= cfg.time_budget)])
        if distributed:
            dist.broadcast(stop, 0)
        if rank == 0:
            append_metrics(run_dir / "metrics.csv", rows, CSV_FIELDS)
            save_checkpoint(payload(epoch + 1, False, states), run_dir / ck.LAST)
            log.info("%s epoch %d/%d: mean loss %.4f m (%.1f s)", kind, epoch + 1, cfg.epochs, mean, time.time() - t_epoch)
        if distributed:
            dist.barrier()
        if bool(stop.item()) and epoch + 1 < cfg.epochs:
            stopped_early = True
            if rank == 0:
                log.warning("time budget of %.0f s spent after epoch %d of %d: stopping", cfg.time_budget, epoch + 1, cfg.epochs)
            break
    done = epoch + 1 if cfg.epochs > start_epoch else start_epoch
    if rank == 0:
        save_checkpoint(payload(done, True), run_dir / ck.FINAL)
    if distributed:
        dist.barrier()
    return {"run_dir": str(run_dir), "kind": kind, "epochs": done, "start_epoch": start_epoch, "steps": steps_run,
            "first_loss": epoch_means[0] if epoch_means else math.nan, "last_loss": epoch_means[-1] if epoch_means else math.nan,
            "val_add": val_add, "stopped_early": stopped_early, "seconds": time.time() - t_start}


def ensure_trained(kind: str, data, run_dir: str | Path, profile: str = "smoke", *, pose_run=None, val=None,
                   progress: bool = False, **overrides) -> dict:
    """Train a run unless it is already complete (for notebooks and pipelines).

    ``run_dir/model.pt`` present: nothing is trained (``status`` ``loaded``); an interrupted run
    (``last.pt`` only) is resumed; otherwise a new run of ``profile`` is trained.

    Args:
        kind: ``"pose"`` or ``"refiner"`` (the latter needs ``pose_run``).
    Returns:
        ``{"status": "loaded" | "resumed" | "trained", ...}`` (the training summary when trained).
    """
    run_dir = Path(run_dir)
    if (run_dir / ck.FINAL).is_file():
        c = ck.load(run_dir / ck.FINAL, kind=kind)
        return {"status": "loaded", "run_dir": str(run_dir), "epochs": c["epoch"]}
    resume = (run_dir / ck.LAST).is_file()
    if kind == "pose":
        s = train_pose(data, run_dir, profile=None if resume else profile, resume=resume, val=val, progress=progress, **overrides)
    else:
        s = train_refiner(pose_run, data, run_dir, profile=None if resume else profile, resume=resume, val=val,
                          progress=progress, **overrides)
    return {"status": "resumed" if resume else "trained", **s}
