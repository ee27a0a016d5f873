"""One training loop for every network of the package (segmentation, main pose network, refiner,
and later ones): single process, or DDP under ``torchrun`` (NCCL on GPUs, gloo on CPU).

A network contributes a small :class:`TrainTask` (its config class, how to open its data and build
its model, one step's losses, an optional validation and its checkpoint header); the engine does
everything else, the same way for all:

* run directory: claim a new one or resume one (``--resume``; only
  :data:`~sixdpose.training.schedule.RESUMABLE` fields may change), refuse to resume on other training
  data (``status.json`` keeps a fingerprint), remove temporary files of a save cut by ``kill -9`` and
  repair a crash-cut ``metrics.csv`` (see :mod:`.rundir`);
* seeding: ``torch.manual_seed(seed)`` before the model is built (identical initialisation on every
  rank), then a per-rank stream ``seed + 7919 * (rank + 1)``; the RNG states of every rank are saved
  with each checkpoint and restored on resume (reseeded, with a warning, when the number of
  processes changed);
* data: every epoch a permutation seeded by ``(seed, epoch)`` is padded to a multiple of the world
  size and rank ``r`` takes every ``world``-th item from ``r``; at most ``max_steps_per_epoch`` steps;
* optimisation: Adam with the learning rate of :func:`~sixdpose.training.schedule.learning_rate` set
  before every step (warm-up and per-epoch decay), autocast + grad scaler when ``amp`` on CUDA,
  gradient-norm clipping; DDP averages the gradients, the logged losses are averaged over ranks;
* non-finite loss: an error (:class:`TrainingError`, "training diverged") without AMP; under AMP the
  scaler skips the update with a warning, and :data:`MAX_SKIPPED` such steps in a row are an error;
* budget: ``time_budget`` seconds (summed over resumes) checked after every step; once spent, the
  epoch ends, is checkpointed and training stops with the final model;
* weight average (``ema_decay`` > 0): an exponential moving average of the parameters after every step
  (:func:`~sixdpose.training.schedule.ema_momentum`), saved in ``last.pt`` as ``ema`` (resumed with it) and
  written as ``model.pt``'s weights; the per-epoch validation scores the raw weights;
* outputs (rank 0 alone writes): ``metrics.csv`` rows, ``last.pt`` after every epoch, ``model.pt``
  at the end, ``status.json`` and ``run.json``; a rank-0 setup error is raised on every rank.

Adding a network (e.g. a dense head): derive its config from
:class:`~sixdpose.training.schedule.TrainSchedule`, subclass :class:`TrainTask` with ``new_config``,
``open`` (optional), ``prepare``, ``load_checkpoint``, ``setup``, ``step`` and ``checkpoint_header``
(``collate``, ``start_epoch``, ``validate``, ``run_info`` when the defaults do not fit), and call
``train(task, run_dir, ...)`` from the stage's entry point (see :class:`sixdpose.pose.train.PoseTask`
and :class:`sixdpose.segmentation.train.SegTask`).
"""

from __future__ import annotations

import logging
import math
import platform
import time
from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.distributed as dist

from ..fileio import atomic_write_json, claim_output_dir, remove_stale_temporaries
from ..runs import (
    FINAL,
    LAST,
    append_metrics,
    process_group,
    rng_state,
    save_checkpoint,
    set_rng_state,
    truncate_metrics,
)
from .rundir import (
    METRICS,
    TrainingError,
    check_same_data,
    prepare_run_dir,
    repair_metrics,
    write_status,
)
from .schedule import TrainSchedule, ema_momentum, learning_rate

log = logging.getLogger("sixdpose.training")

#: Consecutive non-finite losses under AMP (updates skipped by the grad scaler) that end training.
MAX_SKIPPED = 10


@dataclass(frozen=True)
class StepContext:
    """Where a step is: ``epoch`` and ``step`` (0-based, in the epoch), ``global_step`` (steps before this
    one, over all epochs), ``rank``/``world``, the ``device`` and whether AMP is on."""

    epoch: int
    step: int
    global_step: int
    rank: int
    world: int
    device: torch.device
    amp: bool

    def autocast(self):
        """Context manager for the forward pass (float16 autocast under AMP, else nothing)."""
        return torch.autocast("cuda", dtype=torch.float16) if self.amp else nullcontext()


class TrainTask:
    """What one network contributes to :func:`train` (subclass it; the defaults suit most networks).

    Attributes:
        kind: the network's name (progress bars, messages). command: the CLI command that owns the
            run directories (``train-seg``). config_class: its config (a :class:`TrainSchedule`).
        loss_fields: names of extra loss terms that :meth:`step` returns beside ``loss`` (columns of
            ``metrics.csv``). val_fields: columns of the per-epoch row of :meth:`validate`.
        checkpoint_error: the stage's checkpoint exception (an incompatible ``last.pt``).
        timeout_hours: process-group timeout (rank 0 may do long setup work while the others wait).
    """

    kind: str = "network"
    command: str = "train"
    config_class: type = TrainSchedule
    loss_fields: tuple[str, ...] = ()
    val_fields: tuple[str, ...] = ()
    checkpoint_error: type = TrainingError
    timeout_hours: float = 1.0

    def new_config(self, profile: str | None, overrides: dict):
        """Config of a new run: the named profile (None: the default one) with ``overrides``."""
        raise NotImplementedError

    def open(self) -> None:
        """Open and check the inputs (data, an earlier run) before the run directory is claimed, so a bad
        argument writes nothing. Called on rank 0 before :meth:`prepare` and on every rank before
        :meth:`setup`: keep what it opens and return at once when called again."""

    def prepare(self, run_dir: Path, cfg, resume: bool) -> tuple[str, str]:
        """Rank 0, before the config is saved: check the data, write the stage's own files (a split).

        Returns:
            ``(data location, data fingerprint)`` (:func:`~sixdpose.training.rundir.data_fingerprint`).
        """
        raise NotImplementedError

    def load_checkpoint(self, path: Path) -> dict:
        """Read and validate the run's ``last.pt`` (raising :attr:`checkpoint_error`)."""
        raise NotImplementedError

    def setup(self, run_dir: Path, cfg, device: torch.device, rank: int, world: int, last: dict | None):
        """Every rank, after ``torch.manual_seed(cfg.seed)``: open the data, check ``last`` against it and
        build the model on ``device`` (weights from ``last`` are loaded by the engine).

        Returns:
            ``(model, dataset)``: the module whose trainable parameters are optimised, and a map-style
            dataset of training items.
        """
        raise NotImplementedError

    def collate(self, items: list):
        """``collate_fn`` of the data loader (default: the list of items)."""
        return items

    def start_epoch(self, epoch: int, model, net) -> None:
        """Start ``epoch``: select the dataset's random draws of the epoch (if it has any) and put the model in
        training mode (``net``: the DDP wrapper or ``model``). Default: ``net.train()``."""
        net.train()

    def step(self, net, batch, ctx: StepContext) -> dict | None:
        """One step's losses: ``{"loss": scalar tensor, **loss_fields}`` (``loss`` is minimised), or None
        to skip a batch that has nothing to learn from (an error under DDP). Run the forward pass in
        ``ctx.autocast()``; ``net`` is the DDP wrapper under DDP."""
        raise NotImplementedError

    def validate(self, model, epoch: int) -> dict | None:
        """Rank 0, after every epoch: ``{val_field: value}`` for a metrics row, or None (no validation)."""
        return None

    def checkpoint_header(self, cfg) -> dict:
        """The stage's entries of both checkpoints (format, version, config, classes, ...)."""
        raise NotImplementedError

    def run_info(self) -> dict:
        """The stage's entries of ``run.json`` (classes, data, ...)."""
        return {}


def shard(n: int, epoch: int, seed: int, rank: int, world: int) -> list[int]:
    """This rank's item indices of ``epoch``: a permutation of ``range(n)`` seeded by ``(seed, epoch)``,
    padded by its first items to a multiple of ``world``, every ``world``-th item from ``rank``."""
    order = np.random.default_rng([seed, epoch, 7]).permutation(n)
    if len(order) % world:
        order = np.concatenate([order, order[: world - len(order) % world]])
    return order[rank::world].tolist()


def broadcast_error(distributed: bool, err: Exception | None) -> None:
    """Raise ``err`` of rank 0's setup on every rank (the others would otherwise wait in a barrier)."""
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


def train(task: TrainTask, run_dir: str | Path, *, resume: bool = False, profile: str | None = None, cfg=None,
          overrides: dict | None = None, device: str | None = None, progress: bool = True,
          after_step: Callable[[int, int], None] | None = None) -> dict:
    """Train ``task``'s network into ``run_dir`` (see the module docstring).

    Args:
        task: the network. run_dir: the run directory. resume: continue the run in it.
        profile: the config profile (new run; on resume it must be the run's own). cfg: an explicit
            config instead of the profile. overrides: config fields. device: cpu/cuda/auto.
        progress: progress bar (rank 0). after_step: called as ``after_step(epoch, global_step)``
            after every optimiser step (to stop a run from outside, e.g. in tests).
    Returns:
        summary: run_dir, kind, epochs (completed), start_epoch, steps (run now), first_loss/last_loss
        (epoch means of this call), stopped_early, seconds, and the last validation's fields.
    Raises:
        TrainingError, the stage's errors (dataset, checkpoint, config).
    """
    with process_group(device, timeout_hours=task.timeout_hours) as (dev, world, rank):
        return _train(task, Path(run_dir), resume, profile, cfg, dict(overrides or {}), dev, world, rank, progress,
                      after_step)


def _train(task, run_dir, resume, profile, cfg, overrides, dev, world, rank, progress, after_step) -> dict:
    t_start = time.time()
    distributed = world > 1
    err, location, fingerprint = None, "", ""
    if rank == 0:
        try:
            claim_output_dir(run_dir, task.command, create=False)  # refuse a foreign directory before any work
            task.open()
            cfg = prepare_run_dir(run_dir, resume, task.config_class, task.new_config, profile, overrides, task.command,
                                  cfg)
            if resume:
                remove_stale_temporaries(run_dir)
                repair_metrics(run_dir / METRICS)
            location, fingerprint = task.prepare(run_dir, cfg, resume)
            if resume:
                check_same_data(run_dir, location, fingerprint)
            cfg.save(run_dir / "config.json")
        except Exception as e:  # noqa: BLE001 - re-raised on every rank
            err = e
    broadcast_error(distributed, err)
    if distributed:
        dist.barrier()
    task.open()
    cfg = task.config_class.load(run_dir / "config.json")
    if cfg.num_threads > 0:
        torch.set_num_threads(cfg.num_threads)
    last = task.load_checkpoint(run_dir / LAST) if resume and (run_dir / LAST).exists() else None

    torch.manual_seed(cfg.seed)  # identical initialisation on every rank
    model, dataset = task.setup(run_dir, cfg, dev, rank, world, last)
    params = [p for p in model.parameters() if p.requires_grad]
    opt = torch.optim.Adam(params, lr=cfg.lr, weight_decay=cfg.weight_decay)
    use_amp = bool(cfg.amp and dev.type == "cuda")
    scaler = torch.amp.GradScaler("cuda", enabled=use_amp)
    torch.manual_seed(cfg.seed + 7919 * (rank + 1))  # per-rank stream for sampling inside the model
    per_rank = math.ceil(len(dataset) / world)
    steps_per_epoch = math.ceil(per_rank / cfg.batch_size)
    if cfg.max_steps_per_epoch > 0:
        steps_per_epoch = min(steps_per_epoch, cfg.max_steps_per_epoch)
    start_epoch, global_step, elapsed = 0, 0, 0.0
    if last is not None:
        try:
            model.load_state_dict(last["model"])
            opt.load_state_dict(last["optimizer"])
            if use_amp and "scaler" in last:
                scaler.load_state_dict(last["scaler"])
        except (RuntimeError, KeyError, ValueError) as e:
            raise task.checkpoint_error(f"{run_dir / LAST}: incompatible with the run's config "
                                        f"({str(e).splitlines()[0][:200]})") from None
        start_epoch = int(last["epoch"])
        global_step = int(last.get("global_step", start_epoch * steps_per_epoch))
        elapsed = float(last.get("elapsed", 0.0))
        states = last.get("rng") or []
        if last.get("world_size") == world and len(states) == world:
            set_rng_state(states[rank])
        else:
            if rank == 0:
                log.warning("resuming with %d process(es) instead of %s: RNG streams are reseeded", world,
                            last.get("world_size"))
            torch.manual_seed(cfg.seed + 7919 * (rank + 1) + start_epoch)
        if rank == 0:
            log.warning("resuming %s at epoch %d of %d", run_dir, start_epoch + 1, cfg.epochs)
    ema = None
    if cfg.ema_decay > 0:  # the averaged weights (parameters averaged, buffers copied), resumed from last.pt
        ema = {k: v.detach().clone() for k, v in model.state_dict().items()}
        if last is not None and "ema" in last:
            ema.update({k: v.to(ema[k].device) for k, v in last["ema"].items() if k in ema})
        averaged = {k for k, _ in model.named_parameters()}
    fields = ("epoch", "step", "lr", "loss") + tuple(task.loss_fields) + tuple(task.val_fields) + ("seconds",)
    if rank == 0:
        write_status(run_dir, finished=False, epoch=start_epoch, epochs=cfg.epochs, data=location,
                     data_sha256=fingerprint)
        truncate_metrics(run_dir / METRICS, start_epoch, fields)
        atomic_write_json(run_dir / "run.json", {"kind": task.kind, **task.run_info(), "world_size": world,
                                                 "device": str(dev), "amp": use_amp, "torch": torch.__version__,
                                                 "python": platform.python_version()})

    net = model
    if distributed:
        net = torch.nn.parallel.DistributedDataParallel(model, device_ids=[dev.index] if dev.type == "cuda" else None)

    def payload(epoch: int, final: bool, states=None) -> dict:
        d = dict(task.checkpoint_header(cfg))
        weights = model.state_dict()
        if ema is not None and final:
            weights = {k: ema[k].clone() for k in weights}
        d.update(epoch=epoch, global_step=global_step, elapsed=elapsed, model=weights)
        if not final:
            d.update(optimizer=opt.state_dict(), scaler=scaler.state_dict(), rng=states, world_size=world)
            if ema is not None:
                d["ema"] = ema
        return d

    def update_ema() -> None:
        if ema is None:
            return
        m = ema_momentum(cfg.ema_decay, global_step)
        with torch.no_grad():
            for k, v in model.state_dict().items():
                if k in averaged and v.is_floating_point():
                    ema[k].mul_(m).add_(v.detach(), alpha=1.0 - m)
                else:
                    ema[k].copy_(v)

    epoch_means, steps_run, val, stopped_early, skipped = [], 0, {}, False, 0
    done = start_epoch
    for epoch in range(start_epoch, cfg.epochs):
        t_epoch = time.time()
        loader = torch.utils.data.DataLoader(dataset, batch_size=cfg.batch_size,
                                             sampler=shard(len(dataset), epoch, cfg.seed, rank, world),
                                             num_workers=cfg.num_workers, collate_fn=task.collate,
                                             pin_memory=dev.type == "cuda")
        task.start_epoch(epoch, model, net)
        bar = None
        if progress and rank == 0:
            from tqdm.auto import tqdm

            bar = tqdm(total=steps_per_epoch, desc=f"{task.kind} epoch {epoch + 1}/{cfg.epochs}", leave=False,
                       dynamic_ncols=True)
        rows, losses, lr = [], [], learning_rate(cfg, epoch, global_step)
        for step, batch in enumerate(loader):
            if step >= steps_per_epoch:
                break
            lr = learning_rate(cfg, epoch, global_step)
            for g in opt.param_groups:
                g["lr"] = lr
            out = task.step(net, batch, StepContext(epoch, step, global_step, rank, world, dev, use_amp))
            if out is None:
                if distributed:
                    raise TrainingError(f"nothing to learn from in the batch of epoch {epoch + 1} step {step + 1} "
                                        "(under DDP every step needs items: drop images without usable objects)")
                continue
            loss = out["loss"]
            vals = torch.stack([loss.detach().float()] + [out[k].detach().float() for k in task.loss_fields])
            if distributed:
                dist.all_reduce(vals)
                vals /= world
            vals = vals.cpu().tolist()
            if not math.isfinite(vals[0]):
                skipped += 1
                if not use_amp or skipped >= MAX_SKIPPED:
                    times = f" ({skipped} steps in a row)" if use_amp else ""
                    raise TrainingError(f"loss became {vals[0]} at epoch {epoch + 1} step {step + 1}{times}; "
                                        "training diverged (lower lr?)")
                if rank == 0:
                    log.warning("non-finite loss at epoch %d step %d under AMP; the scaler skips this update",
                                epoch + 1, step + 1)
            else:
                skipped = 0
            opt.zero_grad(set_to_none=True)
            scaler.scale(loss).backward()
            if cfg.grad_clip > 0:
                scaler.unscale_(opt)
                torch.nn.utils.clip_grad_norm_(params, cfg.grad_clip)
            scaler.step(opt)
            scaler.update()
            update_ema()
            losses.append(vals[0])
            global_step += 1
            steps_run += 1
            spent = False
            if cfg.time_budget > 0:  # checked after every step: a long epoch cannot overrun the budget
                flag = torch.tensor([float(elapsed + time.time() - t_epoch >= cfg.time_budget)], device=dev)
                if distributed:
                    dist.broadcast(flag, 0)
                spent = bool(flag.item())
            if rank == 0 and (step % cfg.log_every == 0 or step == steps_per_epoch - 1 or spent):
                row = {"epoch": epoch, "step": global_step, "lr": f"{lr:.6g}", "loss": round(vals[0], 6)}
                row.update({k: round(v, 6) for k, v in zip(task.loss_fields, vals[1:], strict=True)})
                row.update({k: "" for k in task.val_fields})
                row["seconds"] = round(time.time() - t_start, 3)
                rows.append(row)
            if bar is not None:
                bar.set_postfix(loss=f"{vals[0]:.4f}")
                bar.update(1)
            if after_step is not None:
                after_step(epoch, global_step)
            if spent:
                if rank == 0 and step + 1 < steps_per_epoch:
                    log.warning("time budget of %.0f s spent at step %d of %d of epoch %d: the rest of the epoch is "
                                "skipped", cfg.time_budget, step + 1, steps_per_epoch, epoch + 1)
                break
        if bar is not None:
            bar.close()
        mean = float(np.mean(losses)) if losses else math.nan
        epoch_means.append(mean)
        elapsed += time.time() - t_epoch
        if rank == 0:
            val = task.validate(model, epoch) or {}
            if val:
                rows.append({"epoch": epoch, "step": global_step, "lr": f"{lr if losses else 0:.6g}",
                             "loss": round(mean, 6),
                             **{k: "" for k in task.loss_fields}, **{k: round(v, 3) for k, v in val.items()},
                             "seconds": round(time.time() - t_start, 3)})
        states = [rng_state()]
        if distributed:
            gathered = [None] * world
            dist.all_gather_object(gathered, states[0])
            states = gathered
        stop = torch.tensor([float(cfg.time_budget > 0 and elapsed >= cfg.time_budget)], device=dev)
        if distributed:
            dist.broadcast(stop, 0)
        done = epoch + 1
        if rank == 0:
            append_metrics(run_dir / METRICS, rows, fields)
            save_checkpoint(payload(done, False, states), run_dir / LAST)
            write_status(run_dir, finished=False, epoch=done, epochs=cfg.epochs, data=location, data_sha256=fingerprint)
            log.info("%s epoch %d/%d: mean loss %.4f (%.1f s)", task.kind, done, cfg.epochs, mean,
                     time.time() - t_epoch)
        if distributed:
            dist.barrier()
        if bool(stop.item()) and done < cfg.epochs:
            stopped_early = True
            if rank == 0:
                log.warning("time budget of %.0f s spent after epoch %d of %d: stopping", cfg.time_budget, done,
                            cfg.epochs)
            break
    if rank == 0:
        save_checkpoint(payload(done, True), run_dir / FINAL)
        write_status(run_dir, finished=True, epoch=done, epochs=cfg.epochs, data=location, data_sha256=fingerprint)
    if distributed:
        dist.barrier()
    return {"run_dir": str(run_dir), "kind": task.kind, "epochs": done, "start_epoch": start_epoch, "steps": steps_run,
            "first_loss": epoch_means[0] if epoch_means else math.nan,
            "last_loss": epoch_means[-1] if epoch_means else math.nan, **val, "stopped_early": stopped_early,
            "seconds": time.time() - t_start}


def ensure_trained(run_dir: str | Path, train_fn: Callable[[bool], dict], loaded: Callable[[Path], dict]) -> dict:
    """Train a run unless it is complete (for notebooks and pipelines).

    ``RUN/model.pt`` present: nothing is trained (``{"status": "loaded", **loaded(model.pt)}``); an
    interrupted run (``last.pt`` only) is resumed with ``train_fn(True)``; otherwise ``train_fn(False)``
    trains a new one. Returns the training summary with a ``status`` of ``resumed`` or ``trained``.
    """
    run_dir = Path(run_dir)
    if (run_dir / FINAL).is_file():
        return {"status": "loaded", "run_dir": str(run_dir), **loaded(run_dir / FINAL)}
    resume = (run_dir / LAST).is_file()
    return {"status": "resumed" if resume else "trained", **train_fn(resume)}
