"""Training of the learned stage: the main network (``train_pose``) and the refiner
(``train_refiner``), two tasks of the one training engine (:mod:`sixdpose.training`): single process,
or DDP under ``torchrun`` (NCCL on GPUs, gloo on CPU).

Run directory after training::

    config.json   the PoseConfig / RefinerConfig of the run
    run.json      classes, world size, device, versions, data (and the pose run for a refiner)
    status.json   finished or not, completed epochs, fingerprint of the training data
    metrics.csv   one row per logged step (epoch, step, lr, loss in metres, seconds) and one per epoch
                  with ``val_add`` (ADD(-S) accuracy in % on ``--val``, GT masks) when a validation set is given
    last.pt       resumable checkpoint, rewritten atomically after every epoch (see :mod:`.checkpoint`)
    model.pt      final weights, written when the epochs are done or the time budget is spent

The learning rate follows :func:`sixdpose.training.learning_rate` (per-step exponential warm-up times a
per-epoch decay). Randomness (shuffling, point and model-point sampling, RGB noise, refiner noise) is
drawn from generators seeded by (seed, epoch, step/item, rank), so a resumed run repeats exactly what an
uninterrupted one does (the RNG states are saved as well).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import torch

from ..datasets.readers import as_reader
from ..training import StepContext, TrainingError, TrainTask, data_fingerprint, learning_rate, read_metrics
from ..training import ensure_trained as _ensure_trained
from ..training import train as _engine_train
from . import checkpoint as ck
from .config import PoseConfig, RefinerConfig, profile_config, refiner_profile_config
from .data import FrameDataset, PoseError, collate_frames, collate_list, sample_model_points
from .dense import canonical_flip, coordinate_targets, dense_loss, flip_loss, model_symmetry, shape_flips, view_flip
from .geometry import compose_refinement, perturb_poses, to_object_frame
from .loss import pose_loss
from .model import build_posenet, build_refiner

log = logging.getLogger("sixdpose.pose")
__all__ = ["PoseTask", "TrainingError", "dataset_classes", "ensure_trained", "learning_rate",
           "read_metrics", "train_pose", "train_refiner", "validate_accuracy"]


def dataset_classes(reader) -> list[list]:
    """``[[obj_id, name, symmetric], ...]`` of every model of a dataset, sorted by id."""
    return [[int(oid), str(name), bool(reader.model(oid).symmetric)] for oid, name in sorted(reader.object_ids.items())]


def validate_accuracy(reader, posenet, cfg, classes, device, refiner=None, iterations: int = 0,
                      limit: int = 0) -> float:
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


class PoseTask(TrainTask):
    """The main pose network (``kind="pose"``) or the refiner on a finished main network (``"refiner"``)
    as a task of the training engine: frames of the reader's images, the ADD(-S)/chamfer loss of
    :func:`~.loss.pose_loss` (metres; the dense head: :func:`~.dense.dense_loss` on the object coordinates
    of :func:`~.dense.coordinate_targets`), ``val_add`` on an optional validation set after every epoch.
    The main network's ``seen`` buffer counts the training instances of every class (inference skips a
    class it never saw)."""

    loss_fields = ()
    val_fields = ("val_add",)
    checkpoint_error = ck.CheckpointError

    def __init__(self, kind: str, data, masks: str = "gt", val=None, pose_run=None):
        self.kind = kind
        self.command = "train-pose" if kind == "pose" else "train-refiner"
        self.config_class = PoseConfig if kind == "pose" else RefinerConfig
        self.data, self.masks, self.val, self.pose_run = data, masks, val, pose_run
        self.reader = self.pose_ckpt = self.val_reader = None

    def new_config(self, profile, overrides):
        """The profile (default ``smoke``) with ``overrides``."""
        fn = profile_config if self.kind == "pose" else refiner_profile_config
        return fn(profile or "smoke", overrides)

    def open(self) -> None:
        """Open the training reader, check ``--masks`` and read the pose run of a refiner."""
        if self.reader is not None:
            return
        reader = as_reader(self.data, split="train")
        if self.masks != "gt" and not Path(self.masks).is_dir():
            raise PoseError(f"{self.masks}: prediction directory not found (use --masks gt for ground-truth masks)")
        if self.masks != "gt":
            from ..artifacts.predictions import check_predictions_dataset

            check_predictions_dataset(self.masks, reader)  # masks of another dataset are refused
        if self.kind == "refiner":
            from .infer import load_posenet

            pose_ckpt = self.pose_ckpt = ck.load(self.pose_run, kind="pose")
            # built here, before the engine seeds the refiner's initialisation
            self.posenet, self.pose_cfg = load_posenet(pose_ckpt, "cpu")
            if self.pose_cfg.head != "paper":
                raise PoseError(f"{pose_ckpt['path']}: the refiner works on the paper head's poses, not on a "
                                f"{self.pose_cfg.head} pose run")
            for p in self.posenet.parameters():
                p.requires_grad_(False)
        self.reader = reader

    def prepare(self, run_dir, cfg, resume):
        """Nothing to write: the data location and fingerprint."""
        return str(self.reader.location), data_fingerprint(self.reader, {"masks": str(self.masks)})

    def load_checkpoint(self, path):
        """The run's ``last.pt`` (of this kind)."""
        return ck.load(path, kind=self.kind)

    def setup(self, run_dir, cfg, device, rank, world, last):
        """Classes, model points, frames and the network (the refiner's main network frozen)."""
        reader, pose_ckpt = self.reader, self.pose_ckpt
        self.cfg, self.device = cfg, device
        if self.kind == "pose":
            classes = dataset_classes(reader)
            crop, margin = cfg.crop, cfg.crop_margin
        else:
            classes = [list(c) for c in pose_ckpt["classes"]]
            self.posenet.to(device)
            crop, margin = self.pose_cfg.crop, self.pose_cfg.crop_margin
            if last is not None:
                try:
                    ck.check_refiner_matches(last, pose_ckpt)
                except ck.CheckpointError as e:
                    raise ck.CheckpointError(f"--pose {pose_ckpt['path']} does not match the run being resumed: "
                                             f"{e}") from None
        if last is not None and [list(c) for c in last["classes"]] != classes:
            raise ck.CheckpointError(f"{last['path']}: the run was trained on other object classes than "
                                     f"{reader.location} has")
        self.classes = classes
        self.class_index = {int(c[0]): k for k, c in enumerate(classes)}
        self.sym = {int(c[0]): bool(c[2]) for c in classes}
        present = set(reader.object_ids)
        if not present & set(self.class_index):
            raise PoseError(f"{reader.location}: none of its objects is a class of the pose run")
        self.model_points = {oid: reader.model(oid).points.astype(np.float32) for oid in self.class_index
                             if oid in present}
        if self.kind == "pose":
            net = build_posenet(cfg, len(classes))
            centres = np.zeros((len(classes), 3), np.float32)
            for oid, pts in self.model_points.items():
                centres[self.class_index[oid]] = (pts.min(0) + pts.max(0)) / 2.0
            net.set_centres(centres)
            net.seen.zero_()  # counted from here (a resumed run's count comes with its weights)
            self.symmetries = {oid: model_symmetry(reader.model(oid)) for oid in self.model_points} \
                if cfg.head == "dense" else {}
            self.flips = {}
            if cfg.head == "dense" and cfg.flips:
                flips = {oid: shape_flips(reader.model(oid), cfg.flips) for oid in self.model_points}
                self.flips = {oid: f for oid, f in flips.items() if len(f.R) > 1}
                net.set_flips({self.class_index[oid]: (f.R, f.t) for oid, f in self.flips.items()})
                log.info("shape flips: %s", ", ".join(f"obj {oid}: {len(f.R)}" for oid, f in sorted(self.flips.items()))
                         or "none")
        else:
            net = build_refiner(cfg, len(classes), int(pose_ckpt["arch"]["emb_dim"]))
        self.val_reader = as_reader(self.val, split="test") if self.val is not None else None
        keys = reader.keys()[: cfg.max_images] if cfg.max_images else reader.keys()
        self.frames = ds = FrameDataset(reader, list(keys) * cfg.repeat, cfg, self.class_index, crop, margin,
                                        masks=self.masks, seed=cfg.seed)
        return net.to(device), ds

    def start_epoch(self, epoch, model, net):
        """The epoch's sampling draws of every frame; training mode."""
        self.frames.set_epoch(epoch)
        net.train()

    def collate(self, items):
        """Frames as a list (collated per step, with the step's random draws)."""
        return collate_list(items)

    def step(self, net, frames, ctx: StepContext):
        """Loss (metres) of one batch of frames; None when no frame has a usable instance."""
        cfg, dev = self.cfg, ctx.device
        is_pose = self.kind == "pose"
        rng = np.random.default_rng([cfg.seed, ctx.epoch, ctx.step, ctx.rank, 11])
        batch = collate_frames(frames, self.class_index, cfg.rgb_noise if is_pose else 0.0, rng,
                               cfg.colour_jitter if is_pose else 0.0)
        insts = batch["instances"]
        if not insts:
            return None
        mp = sample_model_points(self.model_points, [i.obj_id for i in insts], cfg.num_model_points, rng).to(dev)
        symm = torch.tensor([self.sym[i.obj_id] for i in insts], device=dev)
        R_gt, t_gt = batch["R"].to(dev), batch["t"].to(dev)
        cloud, obj = batch["cloud"].to(dev), batch["obj_index"].to(dev)
        images, img_index, choose = batch["images"].to(dev), batch["img_index"].to(dev), batch["choose"].to(dev)
        if is_pose:
            self._count(net, obj, ctx)
        if is_pose and cfg.head == "dense":
            with ctx.autocast():
                out = net(images, img_index, choose, cloud, obj)
            tgs, labels = [], []
            # input_frame=pca: the canonical turn in the frame the network saw the cloud in (its output "frame")
            frames = list(out["frame"].double().cpu().numpy()) if "frame" in out else [None] * len(insts)
            for i, fr in zip(insts, frames, strict=True):
                fl = self.flips.get(i.obj_id)
                if fl is None:  # the object's own symmetries: the loss takes the best candidate
                    tgs.append(coordinate_targets(i.cloud, i.R, i.t, self.symmetries[i.obj_id]))
                    labels.append(0)
                else:  # a shape flip: the canonical turn's coordinates, the turn classified
                    d = view_flip(i.R, i.t, fl) if cfg.flip_canon == "view" else canonical_flip(i.R, fl, fr)
                    tgs.append(coordinate_targets(i.cloud, i.R, i.t, fl)[d:d + 1])
                    labels.append(d)
            S = max(len(x) for x in tgs)
            tg = np.stack([np.concatenate([x, np.repeat(x[:1], S - len(x), axis=0)]) for x in tgs])
            loss, _ = dense_loss(out["coords"].float(), out["conf_logit"].float(), torch.from_numpy(tg).to(dev),
                                 mode=cfg.dense_loss)
            if "flip_logit" in out:
                loss = loss + cfg.flip_weight * flip_loss(out["flip_logit"].float(), torch.tensor(labels, device=dev))
            return {"loss": loss.mean()}
        with ctx.autocast():
            if is_pose:
                out = net(images, img_index, choose, cloud, obj)
                R, t = out["R"].float(), out["t"].float()
            else:
                with torch.no_grad():
                    out = self.posenet(images, img_index, choose, cloud, obj)
                Rn, tn = perturb_poses(out["R"].float().cpu().double().numpy(), out["t"].float().cpu().double().numpy(),
                                       cfg.noise_rot_deg, cfg.noise_trans, rng)
                R = torch.from_numpy(Rn).float().to(dev)
                t = torch.from_numpy(tn).float().to(dev)
                emb = out["emb"].float().detach()
                for _ in range(cfg.iterations):
                    R_r, t_r = net(to_object_frame(cloud, R, t), emb, obj)
                    R, t = compose_refinement(R, t, R_r.float(), t_r.float())
        return {"loss": pose_loss(R.float(), t.float(), R_gt, t_gt, mp, symm).mean()}

    @staticmethod
    def _count(net, obj, ctx: StepContext) -> None:
        """Add the step's instances per class (over every rank) to the network's ``seen`` buffer."""
        model = getattr(net, "module", net)
        counts = torch.bincount(obj, minlength=model.num_classes).to(model.seen.dtype)
        if ctx.world > 1:
            import torch.distributed as dist

            dist.all_reduce(counts)
        with torch.no_grad():
            model.seen.copy_(torch.where(model.seen >= 0, model.seen + counts, model.seen))

    def validate(self, model, epoch):
        """``val_add`` (%) on the validation set, if one was given."""
        if self.val_reader is None:
            return None
        if self.kind == "pose":
            return {"val_add": validate_accuracy(self.val_reader, model, self.cfg, self.classes, self.device)}
        return {"val_add": validate_accuracy(self.val_reader, self.posenet, self.pose_cfg, self.classes, self.device,
                                             refiner=model, iterations=self.cfg.iterations)}

    def checkpoint_header(self, cfg):
        """Format, kind, config, architecture, classes (and the refiner's pose run)."""
        pose = ck.pose_link(self.pose_ckpt) if self.kind == "refiner" else None
        return ck.header(self.kind, cfg, self.classes, pose)

    def run_info(self):
        """Classes, data and masks (and the pose run of a refiner)."""
        info = {"classes": self.classes, "data": str(self.reader.location), "masks": self.masks}
        if self.pose_ckpt is not None:
            info["pose_run"] = self.pose_ckpt["path"]
        return info


def train_pose(data, run_dir, *, profile: str | None = None, resume: bool = False, masks: str = "gt", val=None,
               device: str | None = None, progress: bool = True, after_step=None, **overrides) -> dict:
    """Train the main pose network and write the run directory (see the module docstring).

    Args:
        data: training dataset (reader or path). run_dir: output run directory.
        profile: ``smoke`` | ``cpu`` | ``paper`` (default smoke; on resume the run's own).
        resume: continue the run in ``run_dir`` (``epochs``, ``time_budget``, threads/workers may change).
        masks: ``"gt"`` or a prediction directory (predicted masks matched to GT by IoU >= 0.5).
        val: optional validation dataset (reader or path) scored every epoch into metrics.csv.
        device: cpu/cuda/auto. progress: progress bars. after_step: ``f(epoch, global_step)`` called
            after every step (see :func:`sixdpose.training.train`). **overrides: PoseConfig fields.
    Returns:
        summary dict (run_dir, epochs done, start_epoch, steps, first_loss/last_loss (m), val_add,
        stopped_early, seconds).
    """
    task = PoseTask("pose", data, masks=masks, val=val)
    return _summary(_engine_train(task, run_dir, resume=resume, profile=profile, overrides=overrides, device=device,
                                  progress=progress, after_step=after_step))


def train_refiner(pose_run, data, run_dir, *, profile: str | None = None, resume: bool = False, val=None,
                  device: str | None = None, progress: bool = True, after_step=None, **overrides) -> dict:
    """Train the iterative refiner on a finished main network's (noised) poses.

    Args:
        pose_run: run directory (or checkpoint) of :func:`train_pose`. Other arguments as
            :func:`train_pose` (ground-truth masks; RefinerConfig fields as overrides).
    Raises:
        CheckpointError: the pose run is corrupt, or on resume differs (classes/architecture) from the
            one the refiner was started on.
    """
    task = PoseTask("refiner", data, val=val, pose_run=pose_run)
    return _summary(_engine_train(task, run_dir, resume=resume, profile=profile, overrides=overrides, device=device,
                                  progress=progress, after_step=after_step))


def _summary(s: dict) -> dict:
    s.setdefault("val_add", None)
    return s


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

    def run(resume: bool) -> dict:
        prof = None if resume else profile
        if kind == "pose":
            return train_pose(data, run_dir, profile=prof, resume=resume, val=val, progress=progress, **overrides)
        return train_refiner(pose_run, data, run_dir, profile=prof, resume=resume, val=val, progress=progress,
                             **overrides)

    return _ensure_trained(run_dir, run, lambda p: {"epochs": ck.load(p, kind=kind)["epoch"]})
