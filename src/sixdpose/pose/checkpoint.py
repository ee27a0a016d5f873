"""Checkpoint files of the learned pose stage: atomic writes, validated reads.

``RUN/last.pt`` (rewritten after every epoch) holds everything needed to resume; ``RUN/model.pt``
(written when training finishes or stops on its time budget) holds what inference needs. Both are
plain dictionaries readable with ``torch.load(..., weights_only=True)``::

    format: "sixdpose-pose"   version: CHECKPOINT_VERSION   kind: "pose" | "refiner"
    config: PoseConfig / RefinerConfig .to_dict()      arch: the shape-defining fields
    classes: [[obj_id, name, symmetric], ...]          epoch, global_step, elapsed (training seconds)
    model: state_dict
    (refiner) pose: {"classes", "arch", "run"} of the main network it was trained on
    (last.pt only) optimizer, scaler, rng: [per-rank state], world_size
"""

from __future__ import annotations

from pathlib import Path

from ..errors import SixdposeError
from ..runs import FINAL, LAST, load_checkpoint, resolve_checkpoint  # noqa: F401  (FINAL, LAST re-exported)

FORMAT = "sixdpose-pose"
CHECKPOINT_VERSION = 1


class CheckpointError(SixdposeError):
    """A pose checkpoint is missing, corrupt, or incompatible (other kind, classes or architecture)."""


def pose_link(pose: dict, run: str | Path | None = None) -> dict:
    """A refiner's link to the main network it was trained on: ``{"classes", "arch", "run"}`` of the pose
    checkpoint ``pose`` (as :func:`load` returns it, whose ``path`` is the run; or as :func:`weights` builds it,
    with ``run`` the file it was saved to). :func:`check_refiner_matches` compares a refiner against it."""
    where = run if run is not None else pose.get("path")
    if where is None:
        raise ValueError("pose_link: the pose checkpoint has no 'path'; pass run= (the file it was saved to)")
    return {"classes": [list(c) for c in pose["classes"]], "arch": dict(pose["arch"]), "run": str(where)}


def header(kind: str, cfg, classes: list, pose: dict | None = None) -> dict:
    """The fields every pose-stage checkpoint starts with: format, version, ``kind`` (``pose`` | ``refiner``),
    ``config`` and ``arch`` (:class:`~sixdpose.pose.config.PoseConfig` or ``RefinerConfig``), ``classes``
    ``[[obj_id, name, symmetric], ...]`` and, for a refiner, ``pose``: its main network's :func:`pose_link`.
    The training task and the benchmarks' untrained checkpoints both use it."""
    if kind not in ("pose", "refiner"):
        raise ValueError(f"kind must be 'pose' or 'refiner', got {kind!r}")
    if (kind == "refiner") != (pose is not None):
        raise ValueError("a refiner checkpoint needs its main network's pose_link (pose=), a pose checkpoint none")
    d = {"format": FORMAT, "version": CHECKPOINT_VERSION, "kind": kind, "config": cfg.to_dict(), "arch": cfg.arch(),
         "classes": [list(c) for c in classes]}
    if pose is not None:
        d["pose"] = pose_link(pose, pose["run"])
    return d


def weights(kind: str, cfg, classes: list, state_dict: dict, pose: dict | None = None, epoch: int = 0,
            global_step: int = 0, elapsed: float = 0.0) -> dict:
    """A complete ``model.pt`` checkpoint (:func:`header` plus weights and counters) for a network that was
    not trained by the training task (an untrained one timed by the benchmarks)."""
    return {**header(kind, cfg, classes, pose), "epoch": int(epoch), "global_step": int(global_step),
            "elapsed": float(elapsed), "model": state_dict}


def load(path: str | Path, kind: str | None = None) -> dict:
    """Read and validate a checkpoint (file or run directory) onto the CPU.

    Args:
        path: checkpoint file or run directory. kind: required ``kind`` (``pose`` | ``refiner``) or None.
    Raises:
        CheckpointError: missing, corrupt, not a pose-stage checkpoint, other version or kind, incomplete.
    """
    ckpt = load_checkpoint(path, FORMAT, CHECKPOINT_VERSION, ("kind", "config", "arch", "classes", "model", "epoch"),
                           "pose", CheckpointError)
    path = resolve_checkpoint(path, CheckpointError)
    if kind is not None and ckpt["kind"] != kind:
        raise CheckpointError(f"{path}: a {ckpt['kind']} checkpoint, expected a {kind} checkpoint")
    if ckpt["kind"] == "refiner" and "pose" not in ckpt:
        raise CheckpointError(f"{path}: incomplete refiner checkpoint (no 'pose')")
    ckpt["path"] = str(path)
    return ckpt


def classes_of(ckpt: dict) -> list[tuple[int, str, bool]]:
    """``[(obj_id, name, symmetric), ...]`` of a checkpoint."""
    return [(int(a), str(b), bool(c)) for a, b, c in ckpt["classes"]]


def check_refiner_matches(refiner: dict, pose: dict) -> None:
    """Raise :class:`CheckpointError` unless ``refiner`` was trained on a main network with ``pose``'s
    classes and architecture."""
    want = refiner["pose"]
    if [list(c) for c in want["classes"]] != [list(c) for c in pose["classes"]]:
        raise CheckpointError(
            f"{refiner['path']}: refiner trained for other object classes than the pose run {pose['path']}"
        )
    if dict(want["arch"]) != dict(pose["arch"]):
        diff = sorted(k for k in set(want["arch"]) | set(pose["arch"]) if want["arch"].get(k) != pose["arch"].get(k))
        raise CheckpointError(
            f"{refiner['path']}: refiner trained on a pose run of another architecture than {pose['path']} "
            f"(differs in {', '.join(diff)})"
        )
