"""Inference of the learned stage: batched pose prediction for every instance of a frame.

:class:`Estimator` loads a main-network run (and optionally a refiner run), and turns one
:class:`~sixdpose.datasets.base.Sample` (with ground-truth or predicted masks) into
:class:`~sixdpose.artifacts.poses.PoseEstimate` rows: all usable instances of the frame go through one
batched forward pass (one CNN pass over the image, or over the batch of crops), then ``iterations``
refinement steps (a ``dense`` head instead: per-point object coordinates, then RANSAC + weighted
Kabsch, :mod:`.dense`), then optionally Open3D ICP (the hybrid stage's ``refine_icp`` with the ``default``
registration preset) and/or the hybrid stage's colour verification (``colour_search``). Unusable
instances (too few valid depth pixels, an object id the checkpoint has no class for or whose class
saw no training instance) get score-0 rows with the reason. ``time`` covers everything but disk reads
(paper section V-A).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np
import torch

from ..artifacts.poses import PoseEstimate
from ..constants import MIN_DETECTION_SCORE
from ..datasets.base import DatasetError
from ..geometry import X_from
from . import checkpoint as ck
from .config import PoseConfig, RefinerConfig
from .data import Frame, PoseError, collate_frames, extract_instance
from .geometry import compose_refinement, to_object_frame
from .model import build_posenet, build_refiner

log = logging.getLogger("sixdpose.pose")


def _with_weights(net, ckpt: dict, device):
    """``net`` with the checkpoint's weights, on ``device``, in eval mode; CheckpointError if they do not fit."""
    try:
        net.load_state_dict(ckpt["model"])
    except (RuntimeError, KeyError) as e:
        first = str(e).splitlines()[0][:200]
        raise ck.CheckpointError(f"{ckpt['path']}: weights do not fit the saved architecture ({first})") from None
    return net.to(device).eval()


def load_posenet(ckpt: dict, device="cpu"):
    """``(PoseNet in eval mode, PoseConfig)`` of a validated ``pose`` checkpoint dict."""
    cfg = PoseConfig.from_dict(ckpt["config"])
    net = build_posenet(cfg, len(ckpt["classes"]))
    return _with_weights(net, ckpt, device), cfg


def load_refiner(ckpt: dict, pose_ckpt: dict, device="cpu"):
    """``(Refiner in eval mode, RefinerConfig)`` of a ``refiner`` checkpoint trained on ``pose_ckpt``'s network."""
    ck.check_refiner_matches(ckpt, pose_ckpt)
    cfg = RefinerConfig.from_dict(ckpt["config"])
    net = build_refiner(cfg, len(ckpt["classes"]), int(pose_ckpt["arch"]["emb_dim"]))
    return _with_weights(net, ckpt, device), cfg


def run_networks(posenet, refiner, batch: dict, iterations: int, device, amp: bool = False):
    """Forward a collated batch through the main network and ``iterations`` refiner steps.

    Args:
        posenet: PoseNet. refiner: Refiner or None. batch: :func:`~sixdpose.pose.data.collate_frames`
            output. iterations: refinement steps (ignored without a refiner). amp: autocast on CUDA.
    Returns:
        ``(R (N, 3, 3), t (N, 3))`` float64 numpy, ``X_CO`` in metres.
    """
    on_cuda = torch.device(device).type == "cuda"
    with torch.no_grad(), torch.autocast("cuda", dtype=torch.float16, enabled=amp and on_cuda):
        cloud = batch["cloud"].to(device)
        obj = batch["obj_index"].to(device)
        out = posenet(batch["images"].to(device), batch["img_index"].to(device), batch["choose"].to(device), cloud, obj)
        R, t = out["R"].float(), out["t"].float()
        if refiner is not None:
            emb = out["emb"].float()
            for _ in range(iterations):
                R_r, t_r = refiner(to_object_frame(cloud, R, t), emb, obj)
                R, t = compose_refinement(R, t, R_r.float(), t_r.float())
    return R.cpu().double().numpy(), t.cpu().double().numpy()


def _orthonormalise(R: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(R)
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt))
    return U @ D @ Vt


#: Fields of a pose run's :class:`~.config.PoseConfig` that ``predict-pose --set`` may change: they act
#: on the points sampled per instance at inference, not on the network's shapes.
INFERENCE_FIELDS = ("num_points", "min_points", "ransac_threshold", "ransac_iterations", "flip_choice",
                    "colour_slides")

#: Smallest score of a verified pose (``predict-pose --verify`` writes the verification's score; the
#: evaluation reads a score <= 0 as "no estimate", which a low verification score must not become).
MIN_VERIFIED_SCORE = 1e-6


def _verify_fields() -> tuple[str, ...]:
    """The ``verify_*`` fields of the registration stage's config (the verification's settings)."""
    import dataclasses

    from ..registration import RegistrationConfig

    return tuple(f.name for f in dataclasses.fields(RegistrationConfig) if f.name.startswith("verify_"))


def _split_overrides(overrides: dict) -> tuple[dict, dict]:
    """``(pose run's fields, verification's verify_* fields)`` of ``overrides``."""
    vf = _verify_fields()
    return ({k: v for k, v in overrides.items() if k not in vf}, {k: v for k, v in overrides.items() if k in vf})


def check_inference_overrides(overrides: dict | None) -> dict:
    """``overrides`` checked before any work: only :data:`INFERENCE_FIELDS` of the pose run's config and
    the ``verify_*`` fields of the registration config (the hypothesis verification's settings, used
    with ``--verify``), each of the field's type and bounds. Raises :class:`~sixdpose.errors.ConfigError`."""
    from ..config import check_overrides
    from ..registration import RegistrationConfig

    pose, reg = _split_overrides(dict(overrides or {}))
    # the verify_* fields are named among the allowed ones in the error message
    pose = check_overrides(PoseConfig, pose, INFERENCE_FIELDS + _verify_fields(), "predict-pose")
    if reg:
        RegistrationConfig().replace(**reg)  # type and bounds
    return {**pose, **reg}


class Estimator:
    """Learned 6D pose estimator for one frame at a time (see the module docstring).

    Args:
        pose: main-network run directory or checkpoint file. refiner: refiner run/checkpoint or None.
        iterations: refinement iterations (default: the refiner's training value; 0 = none).
        device: ``cpu``/``cuda``/None (GPU when present). icp: refine each pose with Open3D ICP.
        colour_verify: run the hybrid stage's colour verification on each pose.
        verify: verify each pose's hypotheses against the frame (the hybrid stage's
            :mod:`~sixdpose.registration.hypotheses`, ``predict-pose --verify``; with ``icp`` the best few
            are ICP'd).
        reader: the dataset reader (its models are needed by ``icp`` / ``colour_verify``).
        score_thresh: predicted masks below this score are ignored. seed: point-sampling seed.
        max_batch: most instances per forward pass (crop mode).
        overrides: :data:`INFERENCE_FIELDS` of the pose run's config, and ``verify_*`` fields of the
            registration config (with ``verify``), to change (``predict-pose --set``); the verification
            starts from the ``default`` preset with :data:`~sixdpose.registration.LEARNED_VERIFY`.
        fallback: ``None``, or a global method of the hybrid stage (``"ransac"``, ``"fgr"``,
            ``"super4pcs"``) for the instances whose verified learned pose scores below the
            registration config's ``verify_retry_below`` (the threshold below which ``register``
            retries): that method then registers the instance as ``register --icp --verify`` would
            (``fallback_profile``'s preset, the instance's seed from :func:`~sixdpose.registration.instance_seed`)
            and the better-verified pose is kept. Needs ``verify``. A cascade: the network's pose, checked
            against the frame, where it fits; the slower search only where it does not.
        fallback_profile: the registration preset of the fallback (``"fast"``, the default: RANSAC capped
            at 20,000 iterations, made for verification; ``"default"``; ``"paper"`` is refused, as it
            does not verify).

    Attributes:
        onboarding_s: seconds spent so far building the objects' model-side data on first use (ICP
            references, colour grids, verification surfaces: the objects' onboarding,
            :class:`~sixdpose.registration.ReferenceCache`); :meth:`predict`'s times leave them out and
            ``settings()`` records them.
        amp: half precision (autocast) for the networks on a GPU; False runs them in float32 there, as on
            the CPU (no effect on the CPU). Default: True for the paper head; False for the dense head, whose
            small network ran its frames faster in float32 on an H200 (the casts cost more than they save:
            ``benchmarks/device_pose.sh``, docs/pose.md) and whose accuracy figures were all computed in float32.
    Raises:
        CheckpointError: corrupt/incompatible checkpoints, or a refiner of another pose run.
        ConfigError: a bad override.
    """

    def __init__(self, pose, refiner=None, *, iterations: int | None = None, device: str | None = None,
                 icp: bool = False, colour_verify: bool = False, reader=None,
                 score_thresh: float = MIN_DETECTION_SCORE, seed: int = 0, max_batch: int = 64,
                 overrides: dict | None = None, verify: bool = False, fallback: str | None = None,
                 fallback_profile: str = "fast"):
        from ..runs import pick_device

        dev = pick_device(device)  # auto / None: the GPU when present
        from ..registration import LEARNED_VERIFY

        overrides, reg_overrides = _split_overrides(check_inference_overrides(overrides))
        verify_fields = {**LEARNED_VERIFY, **reg_overrides}  # the verification's defaults, applied once; --set wins
        pose_ckpt = ck.load(pose, kind="pose")
        net, cfg = load_posenet(pose_ckpt, dev)
        cfg = cfg.replace(**overrides) if overrides else cfg
        refiner_ckpt, ref_net, ref_cfg = None, None, None
        if refiner is not None:
            refiner_ckpt = ck.load(refiner, kind="refiner")
            ref_net, ref_cfg = load_refiner(refiner_ckpt, pose_ckpt, dev)
        self._setup(net, cfg, ck.classes_of(pose_ckpt), ref_net, ref_cfg, dev, iterations, icp, colour_verify, reader,
                    score_thresh, seed, max_batch, verify=verify, verify_fields=verify_fields)
        self._setup_fallback(fallback, fallback_profile, verify_fields)
        self.pose_ckpt, self.refiner_ckpt = pose_ckpt, refiner_ckpt

    @classmethod
    def from_networks(cls, posenet, cfg: PoseConfig, classes, refiner=None, refiner_cfg: RefinerConfig | None = None, *,
                      iterations: int | None = None, device="cpu", reader=None,
                      score_thresh: float = MIN_DETECTION_SCORE, seed: int = 0, max_batch: int = 64) -> Estimator:
        """An estimator over networks already in memory (validation during training), without checkpoints.

        Args:
            posenet: PoseNet. cfg: its PoseConfig. classes: ``[(obj_id, name, symmetric), ...]`` in class
                order. refiner, refiner_cfg: Refiner and its RefinerConfig, or None. The other arguments
                as in :class:`Estimator` (no ICP or colour verification).
        """
        from ..registration import LEARNED_VERIFY

        est = cls.__new__(cls)
        est._setup(posenet, cfg, classes, refiner, refiner_cfg, torch.device(device), iterations, False, False, reader,
                   score_thresh, seed, max_batch, verify_fields=dict(LEARNED_VERIFY))
        est.pose_ckpt, est.refiner_ckpt = None, None
        est._setup_fallback(None, "fast", None)
        return est

    def _setup(self, net, cfg, classes, refiner, refiner_cfg, device, iterations, icp, colour_verify, reader,
               score_thresh, seed, max_batch, verify: bool = False, verify_fields: dict | None = None) -> None:
        """Every attribute of an estimator but the checkpoints (shared by both constructors);
        ``verify_fields``: the ``verify_*`` fields of the registration config (LEARNED_VERIFY and the overrides)."""
        self.device, self.net, self.cfg = device, net, cfg
        self.classes = [tuple(c) for c in classes]
        self.class_index = {int(c[0]): k for k, c in enumerate(self.classes)}
        self.refiner, self.refiner_cfg = refiner, (refiner_cfg if refiner is not None else None)
        default_iterations = self.refiner_cfg.iterations if self.refiner_cfg else 0
        self.iterations = default_iterations if iterations is None else int(iterations)
        if self.iterations < 0:
            raise PoseError(f"iterations must be >= 0, got {self.iterations}")
        if self.iterations and self.refiner is None:
            raise PoseError(f"--iterations {self.iterations} needs a refiner run (--refiner)")
        self.dense = getattr(cfg, "head", "paper") == "dense"
        if self.dense and self.refiner is not None:
            raise PoseError("the refiner works on the paper head's poses, not on a dense pose run (drop --refiner)")
        # classes the network saw no training instance of (a count of -1: unknown, predicted as before)
        seen = getattr(net, "seen", None)
        self.unseen = {int(c[0]) for k, c in enumerate(self.classes) if seen is not None and float(seen[k]) == 0}
        self.icp, self.colour_verify, self.verify, self.reader = icp, colour_verify, verify, reader
        self._diameters: dict[int, float] = {}
        self._slide_cache: dict[int, np.ndarray] = {}  # obj_id -> colour_slides' motions (_slides)
        self._flip_host: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # _flips
        self.score_thresh, self.seed, self.max_batch = score_thresh, seed, max_batch
        # half precision (autocast) on a GPU for the paper head; the dense head in float32 (see the docstring)
        self.amp = not self.dense
        self._cache = None
        self.onboarding_s = 0.0
        if (icp or colour_verify or verify) and reader is None:
            raise PoseError("ICP and colour verification need the dataset reader (its object models)")
        # the dense head's flips named by the model's colours (flip_choice): needs the reader's models
        choice = getattr(cfg, "flip_choice", "classifier")
        if choice == "auto":
            choice = "colour" if getattr(cfg, "appearance", "cnn") != "cnn" else "classifier"
        self.colour_flips = bool(self.dense and getattr(net, "flips", 0) and choice == "colour")
        if self.colour_flips and reader is None:
            log.warning("flip_choice=colour needs the dataset reader (its models' colours): the flip classifier "
                        "names the turns instead")
            self.colour_flips = False
        if self.colour_flips:  # compile the colour kernel now, not inside the first frame's time
            from ..registration import warmup_colour

            warmup_colour()
        if icp or colour_verify or verify or self.colour_flips:
            from ..registration import ReferenceCache, get_preset

            # verify_fields carries the learned stage's verification defaults (LEARNED_VERIFY, merged by each
            # constructor), which also set the colour slides' step and elongation
            self.reg_cfg = get_preset("default", verify=verify, **(verify_fields or {}))
            self._symmetric = {int(c[0]) for c in self.classes if len(c) > 2 and c[2]}
            self._texture_off: dict[int, tuple] = {}  # id(cfg) -> (cfg, cfg without the texture search)
            self._cache = ReferenceCache(reader)

    def settings(self) -> dict:
        """What produced the estimates (for the ``.config.yml`` beside a results CSV)."""
        return {
            "pose_run": self.pose_ckpt["path"] if self.pose_ckpt else None, "pose_config": self.cfg.to_dict(),
            "refiner_run": self.refiner_ckpt["path"] if self.refiner_ckpt else None,
            "refiner_config": self.refiner_cfg.to_dict() if self.refiner_cfg else None,
            "iterations": self.iterations, "icp": self.icp, "colour_verify": self.colour_verify,
            "verify": self.verify, "colour_flips": self.colour_flips,
            "verify_config": ({k: getattr(self.reg_cfg, k) for k in _verify_fields()} if self.verify else None),
            "score_thresh": self.score_thresh, "seed": self.seed, "device": str(self.device),
            "half_precision": bool(self.amp and self.device.type == "cuda"),
            "onboarding_s": round(self.onboarding_s, 3),
            "fallback": ({"method": self.fallback, "profile": self.fallback_profile,
                          "below": self.reg_cfg.verify_retry_below,
                          "seed": self.fallback_cfg.seed if self.fallback_cfg else None,
                          "instances_tried": self.fallback_tried,
                          "instances_replaced": self.fallback_won} if self.fallback else None),
        }

    def _setup_fallback(self, fallback: str | None, profile: str, verify_fields: dict | None) -> None:
        """The hybrid fallback of the constructor's ``fallback`` (see the class docstring), verified with
        ``verify_fields`` (as :meth:`_setup`); raises :class:`~sixdpose.pose.data.PoseError` for an unknown
        method or profile or without ``verify``."""
        from ..registration import METHODS, PRESETS, get_preset

        self.fallback, self.fallback_profile, self.fallback_cfg = fallback, profile, None
        self.fallback_tried = self.fallback_won = 0
        if fallback is None:
            return
        if fallback not in METHODS:
            raise PoseError(f"fallback: unknown method {fallback!r} (choose from {', '.join(METHODS)})")
        if profile not in PRESETS or profile == "paper":
            raise PoseError(f"fallback profile: expected one of {', '.join(p for p in PRESETS if p != 'paper')}, "
                            f"got {profile!r}")
        if not self.verify:
            raise PoseError("--fallback needs --verify (the fallback runs where the verified score is low)")
        self.fallback_cfg = get_preset(profile, verify=True, **(verify_fields or {}))
        if self.fallback_cfg.colour_verify:
            from ..registration import warmup_colour

            warmup_colour()

    def predict(self, sample, detections=None) -> list[PoseEstimate]:
        """Estimate the pose of every instance of one frame.

        Args:
            sample: a Sample with rgb and depth (and instance masks when ``detections`` is None).
            detections: predicted :class:`~sixdpose.artifacts.predictions.Detection` list, or None
                for the ground-truth masks.
        Returns:
            one :class:`PoseEstimate` per instance/detection (score-0 rows with a ``reason`` for the
            unusable ones), all with the frame's total ``time`` in seconds: disk reads (the object models
            are read before the clock) and the objects' onboarding (:attr:`onboarding_s`) left out.
        Raises:
            PoseError: the sample lacks rgb/depth, or GT masks are asked for and it has none.
        """
        if self.reader is not None:  # the object models are read from disk before the clock (disk reads)
            for oid in {g.obj_id for g in sample.instances} | {d.obj_id for d in detections or ()}:
                if oid in self.class_index:
                    self._diameter(oid)
        onboarded = self._cache.onboarding_s if self._cache is not None else 0.0
        t0 = time.perf_counter()
        if sample.rgb is None or sample.depth is None:
            raise PoseError(f"scene {sample.scene_id} image {sample.im_id}: the learned stage needs rgb and depth")
        if detections is None:
            if any(g.mask is None for g in sample.instances):
                raise PoseError(f"scene {sample.scene_id} image {sample.im_id}: no ground-truth masks; "
                                "use predicted masks (--masks PRED_DIR)")
            items = [(g.obj_id, 1.0, g.mask) for g in sample.instances]
        else:
            items = [(d.obj_id, d.score, d.mask) for d in detections if d.score >= self.score_thresh]
        rng = np.random.default_rng([self.seed, int(sample.scene_id), int(sample.im_id)])
        keep_points = self.icp or self.colour_verify or self.verify or self.colour_flips
        rows: list[PoseEstimate | None] = [None] * len(items)
        usable = []
        for k, (oid, score, mask) in enumerate(items):
            if oid not in self.class_index:
                rows[k] = PoseEstimate.failed(sample.scene_id, sample.im_id, oid,
                                              f"object id {oid} is not a class of the pose run")
                continue
            if oid in self.unseen:
                rows[k] = PoseEstimate.failed(sample.scene_id, sample.im_id, oid,
                                              f"object id {oid}: the pose run saw no training instance of it")
                continue
            if mask is None or np.shape(mask) != sample.depth.shape:
                rows[k] = PoseEstimate.failed(sample.scene_id, sample.im_id, oid,
                                              "mask missing or of another size than the image")
                continue
            inst = extract_instance(sample.rgb, sample.depth, sample.K, mask, oid, crop=self.cfg.crop,
                                    margin=self.cfg.crop_margin,
                                    num_points=self.cfg.num_points, min_points=self.cfg.min_points, rng=rng, index=k,
                                    score=score, keep_points=keep_points, depth_band=self._diameter(oid),
                                    with_image=self.net.reads_images)  # no crop cut for a network that reads none
            if isinstance(inst, str):
                rows[k] = PoseEstimate.failed(sample.scene_id, sample.im_id, oid, inst)
            else:
                usable.append(inst)
        step = self.max_batch if self.cfg.crop else max(len(usable), 1)
        for s in range(0, len(usable), step):
            chunk = usable[s:s + step]
            batch = collate_frames([Frame(None if self.cfg.crop or not self.net.reads_images else sample.rgb, chunk)],
                                   self.class_index)
            if self.dense:
                R, t, icp_done = self._dense_poses(batch, chunk, np.random.default_rng(
                    [self.seed, int(sample.scene_id), int(sample.im_id), 1]))
            else:
                R, t = run_networks(self.net, self.refiner, batch, self.iterations, self.device, amp=self.amp)
                icp_done = np.zeros(len(chunk), bool)
            for inst, Ri, ti, done in zip(chunk, R, t, icp_done, strict=True):
                Ri = _orthonormalise(Ri)
                Ri, ti, score = self._post(inst, Ri, ti, sample, items[inst.index][2], icp_done=bool(done))
                rows[inst.index] = PoseEstimate(sample.scene_id, sample.im_id, inst.obj_id, score, Ri, ti)
        dt = time.perf_counter() - t0
        if self._cache is not None:  # the objects' first-use model-side data: onboarding, not the image's time
            onboarded = self._cache.onboarding_s - onboarded
            self.onboarding_s += onboarded
            dt = max(dt - onboarded, 0.0)
        for r in rows:
            r.time = dt
            if r.reason:
                log.info("scene %d image %d obj %d: %s", r.scene_id, r.im_id, r.obj_id, r.reason)
        return rows

    def _dense_poses(self, batch: dict, insts, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Poses of a dense-head batch: per-point object coordinates and confidences from the network, then
        :func:`~sixdpose.pose.dense.ransac_kabsch` of the coordinates onto each instance's sampled cloud.
        Returns ``(R (N, 3, 3), t (N, 3), icp_done (N,) bool)``: ``X_CO`` in metres (float64) and whether the
        pose is already the ICP's (ICP ran to name the colour turn and the canonical turn was kept), so that
        :meth:`_post` does not run the same ICP again from where it stopped."""
        from .dense import ransac_kabsch

        dev = self.device
        with torch.no_grad(), torch.autocast("cuda", dtype=torch.float16, enabled=self.amp and dev.type == "cuda"):
            out = self.net(batch["images"].to(dev), batch["img_index"].to(dev), batch["choose"].to(dev),
                           batch["cloud"].to(dev), batch["obj_index"].to(dev))
        coords = out["coords"].float().cpu().double().numpy()
        conf = torch.sigmoid(out["conf_logit"].float()).cpu().double().numpy()
        flip = (out["flip_logit"].float().argmax(dim=1).cpu().numpy() if "flip_logit" in out
                else np.zeros(len(insts), int))
        Rs, ts, done = [], [], []
        for k, (inst, y, c) in enumerate(zip(insts, coords, conf, strict=True)):
            R, t, _ = ransac_kabsch(y, inst.cloud, c, threshold=self.cfg.ransac_threshold,
                                    iterations=self.cfg.ransac_iterations, rng=rng)
            ci = int(batch["obj_index"][k])
            S = self._slides(inst.obj_id) if self.colour_flips else np.zeros((0, 4, 4))
            if self.colour_flips and self.icp and (int(self._flips()[2][ci]) > 1 or len(S)) \
                    and inst.points is not None:
                # the colours name the turn at a pose that ICP has brought onto the cloud: the canonical fit is
                # often a couple of centimetres off, enough for the print of the wrong turn to agree better,
                # and the turns are symmetries of the shape, so one ICP serves them all
                R, t = self._icp(inst, R, t)
                icp_ran = self._cache is not None
            else:
                icp_ran = False
            d, s = self._colour_flip(inst, R, t, ci, S) if self.colour_flips else (None, -1)
            d = int(flip[k]) if d is None else d
            if d:  # the coordinates are the canonical turn's: back to the named turn (a near-symmetry of the
                # shape only, so ICP runs again on it in _post)
                R, t = self._turned(R, t, ci, d)
            if s >= 0:  # slid along the model's long axis (colour_slides): ICP runs again on it in _post
                X = X_from(R, t) @ S[s]
                R, t = X[:3, :3], X[:3, 3]
            Rs.append(R)
            ts.append(t)
            done.append(icp_ran and not d and s < 0)
        return np.stack(Rs), np.stack(ts), np.array(done, bool)

    def _icp(self, inst, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The pose ``(R, t)`` of one instance after the hybrid stage's ICP alone (no colour check, no
        verification: :func:`sixdpose.registration.refine_pose`)."""
        from ..registration import refine_pose

        if self._cache is None:  # no reader: no models to refine against
            return R, t
        r = refine_pose(X_from(R, t), inst.points, inst.obj_id, self._cache, self.reg_cfg, icp=True,
                        colour_verify=False, colors=inst.colors, frame=None)
        return r.X_CO[:3, :3], r.X_CO[:3, 3]

    def _turned(self, R: np.ndarray, t: np.ndarray, ci: int, d: int) -> tuple[np.ndarray, np.ndarray]:
        """The canonical pose ``(R, t)`` of class ``ci`` mapped back by its flip ``d`` (:func:`~.dense.unflip`)."""
        from .dense import unflip

        flip_R, flip_t, _ = self._flips()
        return unflip(R, t, flip_R[ci, d], flip_t[ci, d])

    def _flips(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The network's shape flips as host arrays, copied once: ``flip_R`` (C, F, 3, 3), ``flip_t`` (C, F, 3)
        float64 and ``flip_n`` (C,) int (on a GPU, reading them per instance cost a synchronisation each)."""
        if self._flip_host is None:
            self._flip_host = (self.net.flip_R.double().cpu().numpy(), self.net.flip_t.double().cpu().numpy(),
                               self.net.flip_n.cpu().numpy().astype(int))
        return self._flip_host

    def _colour_flip(self, inst, R: np.ndarray, t: np.ndarray, ci: int,
                     slides: np.ndarray | None = None) -> tuple[int | None, int]:
        """The shape flip and slide whose pose agrees best with the instance's colours
        (:func:`~sixdpose.registration.colour_scores` of every turn of the canonical pose ``(R, t)``, each
        also moved by every one of ``slides``, (S, 4, 4) motions of the object frame, :meth:`_slides`).

        Returns ``(d, s)``: ``d`` the index into the class's turns, or None (the classifier decides) when
        there is nothing to choose or the model has no colours; ``s`` the index into ``slides``, or -1 for
        the pose as fitted (ties keep the fitted turn, unslid)."""
        from ..registration import colour_scores

        n = int(self._flips()[2][ci])
        S = np.zeros((0, 4, 4)) if slides is None else np.asarray(slides, float).reshape(-1, 4, 4)
        if (n < 2 and not len(S)) or inst.points is None or inst.colors is None or self._cache is None:
            return None, -1
        grid, _ = self._cache.colour_grid(inst.obj_id, self.reg_cfg.cv_grid_cells, self.reg_cfg.cv_smooth_rel)
        if grid is None:
            return None, -1
        turns = [X_from(R, t)] + [X_from(*self._turned(R, t, ci, d)) for d in range(1, n)]
        motions = np.concatenate([np.eye(4)[None], S])  # index 0: unslid
        cands = np.einsum("dij,sjk->dsik", np.stack(turns), motions).reshape(-1, 4, 4)
        sc = colour_scores(cands, inst.points, inst.colors, grid, self._diameter(inst.obj_id), self.reg_cfg)
        if not np.isfinite(sc).any():
            return None, -1
        d, s = divmod(int(np.argmax(sc)), len(motions))
        return d, s - 1

    def _slides(self, obj_id: int) -> np.ndarray:
        """The slides (S, 4, 4) of ``obj_id``'s model along its longest principal axis that the colour naming
        scores (``colour_slides`` each way, :func:`~sixdpose.registration.hypotheses.slides` with the
        registration config's ``verify_slide_rel`` and ``verify_slide_min_elong``); none (0, 4, 4) when
        ``colour_slides`` is 0, the model is not elongated, or there is no reader. Cached per object."""
        n = int(self.cfg.colour_slides)
        if n <= 0 or self._cache is None:
            return np.zeros((0, 4, 4))
        if obj_id not in self._slide_cache:
            from ..registration import model_slides

            self._slide_cache[obj_id] = model_slides(self._cache, obj_id, self.reg_cfg, n)
        return self._slide_cache[obj_id]

    def export_slides(self, obj_ids) -> dict[int, np.ndarray]:
        """The colour-named slides (S, 4, 4) of each of ``obj_ids`` (:meth:`_slides`; model-side onboarding data,
        built with Open3D's voxel grid), to be handed to :meth:`preload_slides` of an estimator in a process
        without Open3D (``benchmarks/device_pose.sh``: a lent GPU machine has none)."""
        return {int(o): self._slides(int(o)) for o in obj_ids}

    def preload_slides(self, slides: dict) -> None:
        """Use ``slides`` (obj_id -> (S, 4, 4) motions of the object frame, :meth:`export_slides`) instead of
        building them from the model: the same poses as the estimator that exported them, without Open3D."""
        for o, S in slides.items():
            self._slide_cache[int(o)] = np.asarray(S, dtype=np.float64).reshape(-1, 4, 4)

    def _diameter(self, obj_id: int) -> float:
        """The object's diameter in metres from the reader's model (0.0 without a reader): the depth band
        of :func:`~sixdpose.pose.data.extract_instance` that drops background seen through a mask."""
        if self.reader is None:
            return 0.0
        if obj_id not in self._diameters:
            try:
                self._diameters[obj_id] = float(self.reader.model(obj_id).diameter)
            except (DatasetError, KeyError):  # an object without a model: no filter for it
                self._diameters[obj_id] = 0.0
        return self._diameters[obj_id]

    def _post(self, inst, R, t, sample=None, mask=None, icp_done: bool = False):
        """Optional ICP, colour check and hypothesis verification of one pose: the hybrid stage's
        refinement chain (:func:`sixdpose.registration.refine_pose`, ``default`` preset); ``sample`` and
        the instance's ``mask`` are the frame of the verification. ``icp_done``: the pose is already the
        ICP's (:meth:`_dense_poses`); with ICP alone asked for, it is then returned as it is.

        Returns ``(R, t, score)``: the score is the instance's (the detection's, 1 with GT masks) unless
        the verification ran, whose score in (0, 1] it then is, as ``register --verify`` writes (floored
        at :data:`MIN_VERIFIED_SCORE`, so verifying never turns a pose into "no estimate")."""
        checks = self.colour_verify or self.verify
        if not (self.icp or checks) or (icp_done and not checks):
            return R, t, inst.score
        from ..registration import Frame, refine_pose

        frame = Frame(sample.depth, sample.K, np.asarray(mask, dtype=bool), sample.rgb) if (
            self.verify and sample is not None and mask is not None) else None
        assert self._cache is not None  # _setup builds it whenever ICP or a check is asked for
        cfg = self._for_object(self.reg_cfg, inst.obj_id)
        r = refine_pose(X_from(R, t), inst.points, inst.obj_id, self._cache, cfg, icp=self.icp,
                        colour_verify=self.colour_verify, colors=inst.colors, frame=frame)
        X_CO, verified = r.X_CO, float(r.score)
        if self.fallback and frame is not None and verified < self.reg_cfg.verify_retry_below:
            X_CO, verified = self._fall_back(inst, sample, frame, X_CO, verified)
        score = max(verified, MIN_VERIFIED_SCORE) if frame is not None else inst.score
        return X_CO[:3, :3], X_CO[:3, 3], score

    def _for_object(self, cfg, obj_id: int):
        """``cfg`` (a RegistrationConfig) for one object: without the texture search of its turn
        (``verify_texture_lattice`` 0) for a symmetric class of the checkpoint, whose turn ADD-S does not
        score (a tennis ball), else ``cfg`` itself. The copy is made once per ``cfg`` (a validated replace
        costs about 2 ms, too much per instance)."""
        if not (cfg.verify_texture_lattice and int(obj_id) in self._symmetric):
            return cfg
        hit = self._texture_off.get(id(cfg))
        if hit is None or hit[0] is not cfg:
            hit = self._texture_off[id(cfg)] = (cfg, cfg.replace(verify_texture_lattice=0))
        return hit[1]

    def _fall_back(self, inst, sample, frame, X_CO: np.ndarray, verified: float) -> tuple[np.ndarray, float]:
        """Register one instance whose verified learned pose ``X_CO`` (score ``verified``) fits the frame
        poorly with the fallback method (:func:`sixdpose.registration.estimate_pose`, verified); returns
        the better-verified ``(X_CO, score)``. An error of the fallback keeps the learned pose (logged)."""
        import dataclasses

        from ..registration import estimate_pose, instance_seed

        base, method, cache = self.fallback_cfg, self.fallback, self._cache
        assert base is not None and method is not None and cache is not None  # set by _setup_fallback, _setup
        cfg = dataclasses.replace(self._for_object(base, inst.obj_id),
                                  seed=instance_seed(base.seed, sample.scene_id, sample.im_id, inst.obj_id, inst.index))
        self.fallback_tried += 1
        try:
            r = estimate_pose(inst.points, inst.obj_id, method, cache, cfg, icp=self.icp,
                              colors=inst.colors if cfg.colour_verify else None, frame=frame)
        except Exception as e:  # one instance's numerical failure must not stop the run
            log.warning("scene %d image %d obj %d: fallback %s failed (%s); the learned pose is kept",
                        sample.scene_id, sample.im_id, inst.obj_id, self.fallback, e)
            return X_CO, verified
        if np.isfinite(r.X_CO).all() and float(r.score) > verified:
            self.fallback_won += 1
            return r.X_CO, float(r.score)
        return X_CO, verified


def predict_dataset(data, pose, *, refiner=None, masks: str = "gt", iterations: int | None = None,
                    icp: bool = False, colour_verify: bool = False, verify: bool = False, device: str | None = None,
                    split: str = "test",
                    limit: int = 0, score_thresh: float = MIN_DETECTION_SCORE, progress: bool = False,
                    estimator: Estimator | None = None, indices=None,
                    overrides: dict | None = None, fallback: str | None = None,
                    fallback_profile: str = "fast") -> tuple[list[PoseEstimate], Estimator]:
    """Estimate poses on every image of a dataset (disk reads are not timed).

    Args:
        data: a DatasetReader or a dataset path. pose, refiner, iterations, icp, colour_verify, verify, device,
            score_thresh: see :class:`Estimator`. masks: ``"gt"`` or a prediction directory of
            ``sixdpose segment``. split: BOP split. limit: first N images only (0: all).
            indices: positions in ``reader.keys()`` of the images to predict (None: ``limit`` decides).
            overrides, fallback, fallback_profile: see :class:`Estimator`.
    Returns:
        ``(estimates, estimator)``.
    Raises:
        PredictionError (a corrupt prediction file, named; masks of another dataset), CheckpointError,
        PoseError, DatasetError.
    """
    from ..datasets.readers import as_reader

    reader = as_reader(data, split=split)
    est = estimator or Estimator(pose, refiner, iterations=iterations, device=device, icp=icp,
                                 colour_verify=colour_verify, reader=reader, score_thresh=score_thresh,
                                 overrides=overrides, verify=verify, fallback=fallback,
                                 fallback_profile=fallback_profile)
    if masks != "gt" and not Path(masks).is_dir():
        raise PoseError(f"{masks}: prediction directory not found (use --masks gt for ground-truth masks)")
    if masks != "gt":
        from ..artifacts.predictions import check_predictions_dataset

        check_predictions_dataset(masks, reader)  # masks of another dataset are refused
    keys = reader.keys()
    keys = [keys[i] for i in indices] if indices is not None else (keys[:limit] if limit else keys)
    out: list[PoseEstimate] = []
    from tqdm.auto import tqdm

    for key in tqdm(keys, desc="predict-pose", unit="img", disable=not progress):
        sample = reader.load(key, masks=masks == "gt")
        dets = None
        if masks != "gt":
            from ..artifacts.predictions import read_predictions

            dets = read_predictions(masks, *key)
        out.extend(est.predict(sample, dets))
    return out, est
