"""Mask R-CNN training loop: single process, or multi-process DDP under ``torchrun``.

Run directory ``RUN_DIR`` after training::

    config.json     the SegConfig that trained it (see :mod:`.config`)
    split.json      train/test image keys, split policy, and what the scan skipped or dropped
    manifest.json   copy of the dataset's manifest (if the dataset has one)
    run.json        classes, backbone initialisation, world size, device, versions
    metrics.csv     one row per logged step: epoch, step, lr, loss and each loss term, seconds
    last.pt         resumable checkpoint, rewritten atomically after every epoch
    model.pt        final weights (what ``sixdpose segment --seg RUN_DIR`` loads)

Optimisation follows the paper (section IV-A): Adam, LR decayed by ``lr_gamma`` every
``lr_step_epochs`` epochs (a ``StepLR`` stepped once per epoch). On CUDA, mixed precision (autocast +
GradScaler) is used when ``amp`` is set. Under ``torchrun`` (``WORLD_SIZE > 1``) each process trains on
its shard (``DistributedSampler``) with ``DistributedDataParallel`` (NCCL on GPUs, gloo on CPU);
``batch_size`` is per process, only rank 0 writes files.
"""

from __future__ import annotations

from ..errors import SixdposeError
from ..fileio import atomic_write_json, claim_output_dir
from ..runs import append_metrics, process_group, rng_state, save_checkpoint, set_rng_state, truncate_metrics

import csv
import json
import logging
import math
import platform
import time
from contextlib import nullcontext
from pathlib import Path

import torch
import torch.distributed as dist

from ..datasets.base import DatasetError
from . import checkpoint as ck
from .config import SegConfig, profile_config
from .data import ClassMap, ScanResult, TrainView, collate, make_split, open_part, scan
from .model import build_model, set_train_sizes

log = logging.getLogger("sixdpose.segmentation")

LOSS_KEYS = ("loss_classifier", "loss_box_reg", "loss_mask", "loss_objectness", "loss_rpn_box_reg")
CSV_FIELDS = ("epoch", "step", "lr", "loss") + LOSS_KEYS + ("seconds",)


class TrainingError(SixdposeError):
    """Training cannot start or continue (bad run directory, diverged loss, ...)."""


def _prepare_run_dir(run_dir: Path, resume: bool, cfg: SegConfig | None, profile: str, overrides: dict) -> SegConfig:
    """Decide the config of the run (fresh or resumed) and check the directory state."""
    cfg_path = run_dir / "config.json"
    if resume:
        if not cfg_path.is_file():
            raise TrainingError(f"{run_dir}: nothing to resume (no config.json); start a new run without --resume")
        saved = SegConfig.load(cfg_path)
        if cfg is not None and cfg.replace(epochs=saved.epochs, num_threads=saved.num_threads,
                                           num_workers=saved.num_workers) != saved:
            raise TrainingError(f"{run_dir}: the given config differs from the saved one; resume uses the saved config")
        if profile and profile != saved.profile:
            raise TrainingError(f"{run_dir}: the run was started with profile {saved.profile!r}, not {profile!r}")
        allowed = {"epochs", "num_threads", "num_workers"}
        bad = sorted(k for k, v in overrides.items() if k not in allowed and getattr(saved, k) != v)
        if bad:
            raise TrainingError(f"cannot change {', '.join(bad)} when resuming (only {', '.join(sorted(allowed))})")
        return saved.replace(**{k: v for k, v in overrides.items() if k in allowed})
    if (run_dir / ck.LAST).exists() or (run_dir / ck.FINAL).exists() or cfg_path.exists():
        raise TrainingError(f"{run_dir}: already holds a run; use --resume to continue it or choose another --out")
    claim_output_dir(run_dir, "train-seg")
    if cfg is None:
        cfg = profile_config(profile or "smoke")
    return cfg.replace(**overrides) if overrides else cfg


def train(
    data: str | Path,
    run_dir: str | Path,
    *,
    profile: str | None = None,
    cfg: SegConfig | None = None,
    resume: bool = False,
    device: str | None = None,
    progress: bool = True,
    **overrides,
) -> dict:
    """Train Mask R-CNN on a dataset and write the run directory (see the module docstring).

    Args:
        data: dataset directory (synthetic layout or BOP root).
        run_dir: output run directory (created; must not hold a run unless ``resume``).
        profile: named profile (``smoke`` or ``paper``) used when ``cfg`` is not given (default
            ``smoke`` for a new run; on resume, the run's own, which ``profile`` must match if given).
        cfg: an explicit config (overrides ``profile``).
        resume: continue the run in ``run_dir`` from its last completed epoch, with its saved config
            (``epochs``, ``num_threads`` and ``num_workers`` may be changed).
        device: ``cpu``/``cuda``/``auto`` (default: GPU when present).
        progress: show a progress bar (rank 0).
        **overrides: config fields to change, e.g. ``epochs=2``.
    Returns:
        Summary dict: ``epochs`` completed, ``steps`` run now, ``first_loss``/``last_loss`` (mean of the
        first / last epoch trained in this call), ``init``, ``run_dir``.
    Raises:
        TrainingError, DatasetError, CheckpointError, ValueError (bad config field).
    """
    # long timeout: rank 0 scans the training images (one pass over the data) while the others wait
    with process_group(device, timeout_hours=3.0) as (dev, world, rank):
        return _train(data, Path(run_dir), profile, cfg, resume, dev, progress, overrides, world, rank, world > 1)


def _barrier(distributed: bool) -> None:
    if distributed:
        dist.barrier()


def _broadcast_error(distributed: bool, err: Exception | None) -> None:
    """Make every rank raise if rank 0 failed during setup (otherwise the others hang in a barrier)."""
    if not distributed:
        if err is not None:
            raise err
        return
    msg = [f"{type(err).__name__}: {err}" if err is not None else None]
    dist.broadcast_object_list(msg, src=0)
    if err is not None:
        raise err
    if msg[0] is not None:
        raise TrainingError(f"rank 0 failed: {msg[0]}")


def _train(data, run_dir, profile, cfg, resume, dev, progress, overrides, world, rank, distributed) -> dict:
    t_start = time.time()
    data = Path(data)
    err = None
    cfg_final = None
    if rank == 0:
        try:
            cfg_final = _prepare_run_dir(run_dir, resume, cfg, profile, overrides)
            run_dir.mkdir(parents=True, exist_ok=True)
            split_path = run_dir / "split.json"
            if not split_path.exists():
                # Fresh run (or a resume that died before the split was written).
                split = make_split(data, cfg_final)
                ds, idx = open_part(data, split, "train")
                classes = ClassMap.from_dataset(ds)
                res = scan(ds, idx, classes, cfg_final, num_workers=cfg_final.num_workers)
                split["scan"] = res.to_dict()
                split["classes"] = classes.to_list()
                split["data"] = str(data.resolve())
                cfg_final.save(run_dir / "config.json")
                atomic_write_json(split_path, split)
                if ds.manifest:
                    atomic_write_json(run_dir / "manifest.json", ds.manifest)
            elif resume:
                cfg_final.save(run_dir / "config.json")  # possibly extended epochs
        except Exception as e:  # noqa: BLE001 - re-raised on every rank
            err = e
    _broadcast_error(distributed, err)
    _barrier(distributed)
    if rank != 0:
        cfg_final = SegConfig.load(run_dir / "config.json")
    cfg = cfg_final
    if cfg.num_threads > 0:
        torch.set_num_threads(cfg.num_threads)

    split = json.loads((run_dir / "split.json").read_text())
    ds, _ = open_part(data, split, "train")
    classes = ClassMap.from_list(split["classes"])
    classes.check_compatible(ds)
    res = ScanResult.from_dict(split["scan"])
    view = TrainView(ds, res.usable, classes, cfg, train=True)

    # identical initialisation on every rank
    torch.manual_seed(cfg.seed)
    ckpt = None
    if resume and (run_dir / ck.LAST).exists():
        ckpt = ck.load(run_dir / ck.LAST)
    model, init = build_model(
        cfg, len(classes), init=None if ckpt is None else ckpt.get("init", "random"), verbose=rank == 0
    )
    model.to(dev)
    params = [p for p in model.parameters() if p.requires_grad]
    opt = torch.optim.Adam(params, lr=cfg.lr, weight_decay=cfg.weight_decay)
    sched = torch.optim.lr_scheduler.StepLR(opt, step_size=cfg.lr_step_epochs, gamma=cfg.lr_gamma)
    use_amp = cfg.amp and dev.type == "cuda"
    scaler = torch.amp.GradScaler("cuda", enabled=use_amp)
    start_epoch = 0
    torch.manual_seed(cfg.seed + 7919 * (rank + 1))  # per-rank stream for sampling inside the model
    if ckpt is not None:
        try:
            model.load_state_dict(ckpt["model"])
            opt.load_state_dict(ckpt["optimizer"])
            sched.load_state_dict(ckpt["scheduler"])
            if "scaler" in ckpt and use_amp:
                scaler.load_state_dict(ckpt["scaler"])
        except (RuntimeError, KeyError, ValueError) as e:
            raise ck.CheckpointError(f"{run_dir / ck.LAST}: incompatible with the run's config ({str(e).splitlines()[0]})") from None
        start_epoch = int(ckpt["epoch"])
        states = ckpt.get("rng") or []
        if ckpt.get("world_size") == world and len(states) == world:
            set_rng_state(states[rank])
        else:
            log.warning("resuming with %d process(es) instead of %s: RNG streams are reseeded", world, ckpt.get("world_size"))
            torch.manual_seed(cfg.seed + 7919 * (rank + 1) + start_epoch)
        if rank == 0:
            log.warning("resuming %s at epoch %d of %d", run_dir, start_epoch + 1, cfg.epochs)
    if rank == 0:
        truncate_metrics(run_dir / "metrics.csv", start_epoch, CSV_FIELDS)
        atomic_write_json(run_dir / "run.json", {
            "classes": classes.to_list(),
            "init": init,
            "world_size": world,
            "device": str(dev),
            "amp": use_amp,
            "torch": torch.__version__,
            "python": platform.python_version(),
            "n_train_images": len(res.usable),
            "split_policy": split["policy"],
        })

    ddp_model = model
    if distributed:
        ddp_model = torch.nn.parallel.DistributedDataParallel(model, device_ids=[dev.index] if dev.type == "cuda" else None)

    sampler = torch.utils.data.DistributedSampler(view, num_replicas=world, rank=rank, shuffle=True, seed=cfg.seed)
    loader = torch.utils.data.DataLoader(
        view,
        batch_size=cfg.batch_size,
        sampler=sampler,
        num_workers=cfg.num_workers,
        collate_fn=collate,
        pin_memory=dev.type == "cuda",
        persistent_workers=False,
    )
    steps_per_epoch = len(loader) if cfg.max_steps_per_epoch <= 0 else min(len(loader), cfg.max_steps_per_epoch)
    global_step = start_epoch * steps_per_epoch
    epoch_means: list[float] = []
    steps_run = 0
    for epoch in range(start_epoch, cfg.epochs):
        sampler.set_epoch(epoch)
        view.set_epoch(epoch)
        ddp_model.train()
        set_train_sizes(model, cfg, training=True)
        rows, losses = [], []
        bar = None
        if progress and rank == 0:
            from tqdm.auto import tqdm

            bar = tqdm(total=steps_per_epoch, desc=f"epoch {epoch + 1}/{cfg.epochs}", leave=False, dynamic_ncols=True)
        t0 = time.time()
        for step, (images, targets) in enumerate(loader):
            if step >= steps_per_epoch:
                break
            images = [im.to(dev, non_blocking=True) for im in images]
            targets = [{k: v.to(dev, non_blocking=True) for k, v in t.items()} for t in targets]
            with torch.autocast("cuda", dtype=torch.float16) if use_amp else nullcontext():
                loss_dict = ddp_model(images, targets)
            loss = sum(loss_dict.values())
            if not torch.isfinite(loss):
                if not use_amp:
                    raise TrainingError(
                        f"loss became {loss.item()} at epoch {epoch + 1} step {step + 1}; training diverged (lower lr?)"
                    )
                # under AMP the grad scaler skips the update (on every rank, the gradients being all-reduced)
                log.warning("non-finite loss at epoch %d step %d under AMP; the scaler skips this update", epoch + 1, step + 1)
            opt.zero_grad(set_to_none=True)
            scaler.scale(loss).backward()
            if cfg.grad_clip > 0:
                scaler.unscale_(opt)
                torch.nn.utils.clip_grad_norm_(params, cfg.grad_clip)
            scaler.step(opt)
            scaler.update()
            vals = torch.stack([loss.detach()] + [loss_dict[k].detach() for k in LOSS_KEYS]).float()
            if distributed:
                dist.all_reduce(vals)
                vals /= world
            vals = vals.cpu().tolist()
            losses.append(vals[0])
            global_step += 1
            steps_run += 1
            if rank == 0 and (step % cfg.log_every == 0 or step == steps_per_epoch - 1):
                row = {"epoch": epoch, "step": global_step, "lr": opt.param_groups[0]["lr"], "loss": round(vals[0], 6)}
                row.update({k: round(v, 6) for k, v in zip(LOSS_KEYS, vals[1:])})
                row["seconds"] = round(time.time() - t_start, 3)
                rows.append(row)
            if bar is not None:
                bar.set_postfix(loss=f"{vals[0]:.3f}")
                bar.update(1)
        if bar is not None:
            bar.close()
        sched.step()
        mean = float(sum(losses) / max(len(losses), 1)) if losses else math.nan
        epoch_means.append(mean)
        # checkpoint: gather every rank's RNG state so a resume with the same world size is exact
        states = [rng_state()]
        if distributed:
            gathered = [None] * world
            dist.all_gather_object(gathered, states[0])
            states = gathered
        if rank == 0:
            append_metrics(run_dir / "metrics.csv", rows, CSV_FIELDS)
            save_checkpoint(
                {
                    "format": ck.FORMAT,
                    "version": ck.CHECKPOINT_VERSION,
                    "config": cfg.to_dict(),
                    "classes": classes.to_list(),
                    "init": init,
                    "epoch": epoch + 1,
                    "model": model.state_dict(),
                    "optimizer": opt.state_dict(),
                    "scheduler": sched.state_dict(),
                    "scaler": scaler.state_dict(),
                    "rng": states,
                    "world_size": world,
                },
                run_dir / ck.LAST,
            )
            log.info("epoch %d/%d: mean loss %.4f (%.1f s)", epoch + 1, cfg.epochs, mean, time.time() - t0)
        _barrier(distributed)
    if rank == 0:
        save_checkpoint(
            {
                "format": ck.FORMAT,
                "version": ck.CHECKPOINT_VERSION,
                "config": cfg.to_dict(),
                "classes": classes.to_list(),
                "init": init,
                "epoch": cfg.epochs,
                "model": model.state_dict(),
            },
            run_dir / ck.FINAL,
        )
    _barrier(distributed)
    return {
        "run_dir": str(run_dir),
        "epochs": cfg.epochs,
        "start_epoch": start_epoch,
        "steps": steps_run,
        "first_loss": epoch_means[0] if epoch_means else math.nan,
        "last_loss": epoch_means[-1] if epoch_means else math.nan,
        "init": init,
        "seconds": time.time() - t_start,
    }


def read_metrics(run_dir: str | Path) -> list[dict]:
    """The rows of ``RUN_DIR/metrics.csv`` with numeric values."""
    path = Path(run_dir) / "metrics.csv"
    if not path.is_file():
        raise DatasetError(f"{path}: no metrics (training has not completed an epoch)")
    with open(path, newline="") as f:
        return [{k: (int(v) if k in ("epoch", "step") else float(v)) for k, v in r.items()} for r in csv.DictReader(f)]


def ensure_trained(data: str | Path, run_dir: str | Path, profile: str = "smoke", *, progress: bool = True,
                   **overrides) -> dict:
    """Train a run unless it is already complete (for notebooks and pipelines).

    ``run_dir/model.pt`` present: nothing is trained (``{"status": "loaded"}``); an interrupted run
    (``last.pt`` only) is resumed; otherwise a new run of ``profile`` is trained on ``data``.
    Returns the :func:`train` summary with a ``status`` of ``loaded``, ``resumed`` or ``trained``.
    """
    run_dir = Path(run_dir)
    if (run_dir / ck.FINAL).is_file():
        c = ck.load(run_dir / ck.FINAL)
        return {"status": "loaded", "run_dir": str(run_dir), "epochs": c["epoch"], "init": c.get("init"),
                "profile": c["config"].get("profile")}
    if (run_dir / ck.LAST).is_file():
        s = train(data, run_dir, resume=True, progress=progress)
        return {"status": "resumed", **s}
    s = train(data, run_dir, profile=profile, progress=progress, **overrides)
    return {"status": "trained", **s}
