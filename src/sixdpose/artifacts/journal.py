"""The journal of a batch pose run: the rows of every finished image, so a stopped run resumes.

``sixdpose register`` writes ``<out>.journal`` beside its results CSV while it runs: a JSON-lines file
whose first line names the run (its ``fingerprint``: method, settings, masks, dataset, images) and whose
every further line holds one finished image (its index, its :class:`~sixdpose.artifacts.poses.PoseEstimate`
rows with their reasons, whether it could be read, its onboarding seconds). Each line is flushed and
synced to disk before the next image, so a run killed at any point (Ctrl-C, the session's end, a lost
machine) loses at most the images in flight. Run again with the same arguments, the run reads the journal,
skips the images it holds and registers the rest; the CSV it then writes has the rows an uninterrupted run
writes (the rows are stored exactly: JSON keeps every float's digits, and the instances' seeds do not
depend on the order of the images). Once the CSV is written the journal is deleted.

A journal whose first line names another run (other settings, masks or images) is not used: it is
replaced, with a log line. A last line cut short by the kill is ignored.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import TextIO

import numpy as np

from ..fileio import atomic_write_text
from .poses import PoseEstimate

log = logging.getLogger(__name__)

#: First key of a journal's first line (what marks the file as ours).
JOURNAL_KIND = "sixdpose-pose-journal"


def journal_path(out: str | Path) -> Path:
    """The journal of the results CSV ``out``: ``<out>.journal`` beside it."""
    out = Path(out)
    return out.with_name(out.name + ".journal")


def _row_to_json(r: PoseEstimate) -> list:
    return [int(r.scene_id), int(r.im_id), int(r.obj_id), float(r.score),
            [float(v) for v in np.asarray(r.R, dtype=np.float64).reshape(-1)],
            [float(v) for v in np.asarray(r.t, dtype=np.float64).reshape(-1)], float(r.time), str(r.reason)]


def _row_from_json(v: list) -> PoseEstimate:
    s, i, o, score, R, t, tm, reason = v
    return PoseEstimate(int(s), int(i), int(o), float(score), np.asarray(R, dtype=np.float64).reshape(3, 3),
                        np.asarray(t, dtype=np.float64).reshape(3), float(tm), str(reason))


class ImageJournal:
    """Append-only record of the finished images of one batch run (see the module docstring).

    Args:
        path: the journal file (:func:`journal_path` of the results CSV).
        fingerprint: a JSON-serialisable dict naming the run; a journal is resumed only when its
            fingerprint is equal.
        resume: False: an existing journal is discarded and the run starts over.

    Attributes:
        done: ``{image index: (rows, failure or None, onboarding seconds)}`` read from the journal.
    """

    def __init__(self, path: str | Path, fingerprint: dict, resume: bool = True):
        self.path = Path(path)
        self.fingerprint = json.loads(json.dumps(fingerprint))  # as it reads back (tuples -> lists)
        self.done: dict[int, tuple[list[PoseEstimate], tuple | None, float]] = {}
        self._f: TextIO | None = None
        if resume and self.path.is_file():
            self._read()
        elif self.path.exists() and not resume:
            log.warning("%s: discarding the journal of an earlier run (--no-resume)", self.path)

    def _read(self) -> None:
        with open(self.path, encoding="utf-8", errors="replace") as f:
            lines = f.read().split("\n")
        try:
            head = json.loads(lines[0])
        except ValueError:
            head = None
        if not isinstance(head, dict) or head.get("kind") != JOURNAL_KIND:
            log.warning("%s: not a journal of sixdpose; it will be replaced", self.path)
            return
        if head.get("fingerprint") != self.fingerprint:
            log.warning("%s: the journal of a run with other arguments; starting over", self.path)
            return
        for n, line in enumerate(lines[1:], start=2):
            if not line.strip():
                continue
            try:
                e = json.loads(line)
                rows = [_row_from_json(v) for v in e["rows"]]
                fail = tuple(e["fail"]) if e.get("fail") else None
                self.done[int(e["i"])] = (rows, fail, float(e.get("onb", 0.0)))
            except (ValueError, KeyError, TypeError) as err:  # a line cut short by the kill
                log.warning("%s: line %d unreadable (%s); that image is run again", self.path, n, err)
        if self.done:
            log.warning("%s: resuming: %d image(s) already done", self.path, len(self.done))

    def open(self, keep=None) -> ImageJournal:
        """Start writing: rewrite the file atomically with the header and the entries of :attr:`done`, only
        those of the image indices ``keep`` when it is given (the images of this run)."""
        if keep is not None:
            keep = set(keep)
            self.done = {i: v for i, v in self.done.items() if i in keep}
        lines = [json.dumps({"kind": JOURNAL_KIND, "fingerprint": self.fingerprint}) + "\n"]
        lines += [self._line(i, rows, fail, onb) for i, (rows, fail, onb) in sorted(self.done.items())]
        atomic_write_text(self.path, "".join(lines))
        self._f = self._open_for_append()
        return self

    def _open_for_append(self) -> TextIO:
        """The journal opened for appending (each :meth:`add` flushes and syncs its line)."""
        return open(self.path, "a", encoding="utf-8")  # noqa: SIM115 (closed by close/remove)

    @staticmethod
    def _line(i: int, rows, fail, onb: float) -> str:
        return json.dumps({"i": int(i), "rows": [_row_to_json(r) for r in rows],
                           "fail": list(fail) if fail else None, "onb": float(onb)}) + "\n"

    def add(self, i: int, rows: list[PoseEstimate], fail: tuple | None, onboarding_s: float) -> None:
        """Record finished image ``i`` (flushed and synced before returning)."""
        self.done[int(i)] = (list(rows), fail, float(onboarding_s))
        if self._f is not None:
            self._f.write(self._line(i, rows, fail, onboarding_s))
            self._f.flush()
            os.fsync(self._f.fileno())

    def close(self) -> None:
        """Stop writing; the file stays (a later run resumes from it)."""
        if self._f is not None:
            self._f.close()
            self._f = None

    def remove(self) -> None:
        """Close and delete the journal (once the results it holds are written elsewhere)."""
        self.close()
        self.path.unlink(missing_ok=True)
