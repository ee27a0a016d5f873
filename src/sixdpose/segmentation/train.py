"""Mask R-CNN training: a task of the one training engine (:mod:`sixdpose.training`), single process
or multi-process DDP under ``torchrun``.

Run directory ``RUN_DIR`` after training::

    config.json     the SegConfig that trained it (see :mod:`.config`)
    split.json      train/test image keys, split policy, and what the scan skipped or dropped
    manifest.json   copy of the dataset's manifest (if the dataset has one)
    run.json        classes, backbone initialisation, world size, device, versions
    status.json     finished or not, completed epochs, fingerprint of the training data
    metrics.csv     one row per logged step: epoch, step, lr, loss and each loss term, seconds
    last.pt         resumable checkpoint, rewritten atomically after every epoch
    model.pt        final weights (what ``sixdpose segment --seg RUN_DIR`` loads)

Optimisation follows the paper (section IV-A): Adam, LR decayed by ``lr_gamma`` every
``lr_step_epochs`` epochs (the engine's schedule, :func:`sixdpose.training.learning_rate`). On CUDA,
mixed precision is used when ``amp`` is set. Under ``torchrun`` (``WORLD_SIZE > 1``) each process trains
on its shard of every epoch's permutation, gradients averaged over processes (NCCL on GPUs, gloo on
CPU); ``batch_size`` is per process, only rank 0 writes files.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

from ..datasets.readers import open_dataset
from ..fileio import atomic_write_json
from ..training import TrainingError, TrainTask, data_fingerprint, read_metrics
from ..training import ensure_trained as _ensure_trained
from ..training import train as _engine_train
from . import checkpoint as ck
from .config import SegConfig, profile_config
from .data import ClassMap, ScanResult, TrainView, collate, make_split, open_part, scan
from .model import build_model, set_train_sizes

log = logging.getLogger("sixdpose.segmentation")

LOSS_KEYS = ("loss_classifier", "loss_box_reg", "loss_mask", "loss_objectness", "loss_rpn_box_reg")
__all__ = ["LOSS_KEYS", "SegTask", "TrainingError", "ensure_trained", "read_metrics", "train"]


class SegTask(TrainTask):
    """Mask R-CNN as a task of the training engine: the run's split (made and scanned by rank 0 on a new
    run), torchvision's loss terms (their sum is minimised), the backbone initialisation recorded."""

    kind = "segmentation"
    command = "train-seg"
    config_class = SegConfig
    loss_fields = LOSS_KEYS
    checkpoint_error = ck.CheckpointError
    timeout_hours = 3.0  # rank 0 scans the training images (one pass over the data) while the others wait

    def __init__(self, data):
        self.data = Path(data)

    def new_config(self, profile, overrides):
        """The profile (default ``smoke``) with ``overrides``."""
        return profile_config(profile or "smoke", **overrides)

    def prepare(self, run_dir, cfg, resume):
        """Make, scan and write the split of a new run (or of a resume that died before it was written)."""
        split_path = run_dir / "split.json"
        if not resume or not split_path.exists():
            split = make_split(self.data, cfg)
            ds, idx = open_part(self.data, split, "train")
            classes = ClassMap.from_dataset(ds)
            res = scan(ds, idx, classes, cfg, num_workers=cfg.num_workers)
            split["scan"] = res.to_dict()
            split["classes"] = classes.to_list()
            split["data"] = str(self.data.resolve())
            atomic_write_json(split_path, split)
            if ds.manifest:
                atomic_write_json(run_dir / "manifest.json", ds.manifest)
        split = json.loads(split_path.read_text())
        reader = open_dataset(self.data, split=split["train"]["split"] or "test")
        return str(self.data), data_fingerprint(reader, split["train"]["keys"])

    def load_checkpoint(self, path):
        """The run's ``last.pt``."""
        return ck.load(path)

    def setup(self, run_dir, cfg, device, rank, world, last):
        """The training view of the split and the model (initialisation: the checkpoint's on resume)."""
        self.split = json.loads((run_dir / "split.json").read_text())
        ds, _ = open_part(self.data, self.split, "train")
        self.classes = ClassMap.from_list(self.split["classes"])
        self.classes.check_compatible(ds)
        self.res = ScanResult.from_dict(self.split["scan"])
        self.view = view = TrainView(ds, self.res.usable, self.classes, cfg, train=True)
        init = None if last is None else last.get("init", "random")
        model, self.init = build_model(cfg, len(self.classes), init=init, verbose=rank == 0)
        self.cfg = cfg
        return model.to(device), view

    def collate(self, items):
        """Images and targets as lists."""
        return collate(items)

    def start_epoch(self, epoch, model, net):
        """The epoch's augmentation draws; training mode with the multi-scale training sizes."""
        self.view.set_epoch(epoch)
        net.train()
        set_train_sizes(model, self.cfg, training=True)

    def step(self, net, batch, ctx):
        """torchvision's loss terms of one batch; ``loss`` is their sum."""
        images, targets = batch
        images = [im.to(ctx.device, non_blocking=True) for im in images]
        targets = [{k: v.to(ctx.device, non_blocking=True) for k, v in t.items()} for t in targets]
        with ctx.autocast():
            loss_dict = net(images, targets)
        return {"loss": sum(loss_dict.values()), **{k: loss_dict[k] for k in LOSS_KEYS}}

    def checkpoint_header(self, cfg):
        """Format, config, classes and the backbone initialisation."""
        return ck.header(cfg, self.classes.to_list(), self.init)

    def run_info(self):
        """Classes, initialisation, number of training images and the split policy."""
        return {"classes": self.classes.to_list(), "init": self.init, "n_train_images": len(self.res.usable),
                "split_policy": self.split["policy"], "data": str(self.data)}


def train(
    data: str | Path,
    run_dir: str | Path,
    *,
    profile: str | None = None,
    cfg: SegConfig | None = None,
    resume: bool = False,
    device: str | None = None,
    progress: bool = True,
    after_step=None,
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
            (``epochs``, ``time_budget``, ``num_threads``, ``num_workers`` and ``log_every`` may be
            changed) on the same data.
        device: ``cpu``/``cuda``/``auto`` (default: GPU when present).
        progress: show a progress bar (rank 0).
        after_step: ``f(epoch, global_step)`` called after every step (see :func:`sixdpose.training.train`).
        **overrides: config fields to change, e.g. ``epochs=2``.
    Returns:
        Summary dict: ``epochs`` completed, ``steps`` run now, ``first_loss``/``last_loss`` (mean of the
        first / last epoch trained in this call), ``init``, ``run_dir``, ``stopped_early``.
    Raises:
        TrainingError, DatasetError, CheckpointError, ConfigError (bad config field).
    """
    task = SegTask(data)
    s = _engine_train(task, run_dir, resume=resume, profile=profile, cfg=cfg, overrides=overrides, device=device,
                      progress=progress, after_step=after_step)
    return {**s, "init": task.init}


def ensure_trained(data: str | Path, run_dir: str | Path, profile: str = "smoke", *, progress: bool = True,
                   **overrides) -> dict:
    """Train a run unless it is already complete (for notebooks and pipelines).

    ``run_dir/model.pt`` present: nothing is trained (``{"status": "loaded"}``); an interrupted run
    (``last.pt`` only) is resumed; otherwise a new run of ``profile`` is trained on ``data``.
    Returns the :func:`train` summary with a ``status`` of ``loaded``, ``resumed`` or ``trained``.
    """

    def run(resume: bool) -> dict:
        if resume:
            return train(data, run_dir, resume=True, progress=progress)
        return train(data, run_dir, profile=profile, progress=progress, **overrides)

    def loaded(path: Path) -> dict:
        c = ck.load(path)
        return {"epochs": c["epoch"], "init": c.get("init"), "profile": c["config"].get("profile")}

    return _ensure_trained(run_dir, run, loaded)
