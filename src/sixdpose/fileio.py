"""File writing shared by every stage: atomic writes and the one check that an output directory is
ours before anything is written into it.

Atomic: data goes to a temporary file in the destination's directory and is moved into place with
``os.replace``, so a reader (or a run killed at any moment) sees the old file or the new one, never half
of one.

Ownership: a command writes into a directory only if it is new, empty, or was written by the same kind
of command before. Directories claimed by :func:`claim_output_dir` carry a small marker file
(:data:`MARKER`, JSON ``{"kind": ...}``); a directory may also be recognised by a file the stage writes
anyway (the generator's ``config.yml``, an asset directory's ``objects.csv``). Files are checked by
:func:`claim_output_file`.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import re
from pathlib import Path

from .errors import OutputError

#: Marker file that records which command owns an output directory.
MARKER = ".sixdpose.json"


#: Names of the temporary files of :func:`atomic_path` (``.NAME.tmpPID``, see :func:`_tmp_path`; a suffix
#: some writers append is allowed).
_TMP = re.compile(r"^\..+\.tmp\d+(\.[^.]+)?$")


def _tmp_path(path: Path) -> Path:
    return path.with_name(f".{path.name}.tmp{os.getpid()}")


def remove_stale_temporaries(directory: Path) -> list[Path]:
    """Delete the temporary files of :func:`atomic_path` that a killed process left in ``directory``
    (one warning line naming them); returns them."""
    stale = [p for p in sorted(Path(directory).iterdir()) if p.is_file() and _TMP.match(p.name)]
    for p in stale:
        p.unlink()
    if stale:
        logging.getLogger("sixdpose").warning("%s: removed %d stale temporary file(s) of an interrupted save (%s)",
                                              directory, len(stale), ", ".join(p.name for p in stale))
    return stale


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike):
    """Context manager yielding a temporary path beside ``path``; on success it replaces ``path``.

    Use it with writers that take a path (``np.savez``, ``torch.save``, PIL). On an exception the
    temporary file is removed and ``path`` is untouched. The parent directory is created.

    Example::

        with atomic_path(out / "x.npz") as tmp:
            np.savez_compressed(tmp, a=a)   # note: give savez a file object or a name ending in .npz
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp_path(path)
    if path.suffix:  # keep the suffix: some writers (numpy, PIL) choose the format by it
        tmp = tmp.with_name(tmp.name + path.suffix)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (see the module docstring); returns ``path``."""
    path = Path(path)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(data)
    return path


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically; returns ``path``."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def write_if_changed(path: str | os.PathLike, data: bytes | str) -> bool:
    """Write ``data`` (bytes, or text written as UTF-8) to ``path`` atomically unless the file already
    holds exactly these bytes; returns True if it was written.

    A re-run that would produce the same file leaves it (and its modification time) untouched, so a
    make target keyed on it stays up to date (``make reproduce`` resumes instead of starting over).
    """
    path = Path(path)
    data = data.encode("utf-8") if isinstance(data, str) else data
    try:
        if path.is_file() and path.stat().st_size == len(data) and path.read_bytes() == data:
            return False
    except OSError:
        pass
    atomic_write_bytes(path, data)
    return True


def atomic_write_json(path: str | os.PathLike, obj, indent: int | None = 1, sort_keys: bool = False) -> Path:
    """Write ``obj`` as JSON (plus a newline) to ``path`` atomically; returns ``path``."""
    return atomic_write_text(path, json.dumps(obj, indent=indent, sort_keys=sort_keys) + "\n")


def _check_writable(path: Path) -> None:
    parent = path if path.is_dir() else path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise OutputError(f"{path}: cannot create it: {parent} is a file, not a directory")
    if not os.access(parent, os.W_OK):
        raise OutputError(f"{path}: cannot write here (no write permission in {parent})")


def check_output_location(path: str | os.PathLike, directory: bool = True) -> Path:
    """Check, before any work, that ``path`` can be created or written: for a directory (``directory``)
    it is not an existing file; no ancestor is a regular file; the nearest existing directory is writable.
    Nothing is created. Use it for shared output directories (``--figures``, ``--results-dir``) that
    several commands write into, where :func:`claim_output_dir`'s ownership rule does not apply.

    Raises:
        OutputError: one line naming the path and the reason.
    """
    path = Path(path)
    if directory and path.exists() and not path.is_dir():
        raise OutputError(f"{path}: exists and is not a directory")
    if not directory and path.is_dir():
        raise OutputError(f"{path}: is a directory; expected a file name")
    if path.is_dir() and not os.access(path, os.W_OK):
        raise OutputError(f"{path}: directory is not writable")
    _check_writable(path)
    return path


def check_path_name(name: str, what: str = "name") -> str:
    """Check that ``name`` (a split, a tag, a result or run name) is one plain path component: not
    empty, no ``/`` or ``\\``, not ``.`` or ``..``, no NUL, not absolute. Returns ``name``.

    Raises:
        OutputError: one line naming ``what`` and the value.
    """
    if (not isinstance(name, str) or not name or name in (".", "..") or "/" in name or "\\" in name
            or "\0" in name or os.path.isabs(name) or name != name.strip()):
        raise OutputError(f"{what} {name!r}: expected a plain name (one path component: no '/', '\\', "
                          "'..', leading or trailing space, or absolute path)")
    return name


def claim_output_dir(path: str | os.PathLike, kind: str, marker: str | tuple[str, ...] = (),
                     write_marker: bool = True, create: bool = True) -> bool:
    """Check that ``path`` may receive the output of command ``kind`` and create it.

    Accepted: a path that does not exist, an empty directory, or a directory written by ``kind`` before:
    its :data:`MARKER` names ``kind``, or it contains one of the files named in ``marker`` (a file
    the stage writes anyway, such as the generator's ``config.yml``). A new directory gets the marker
    file unless ``write_marker`` is False.

    Args:
        path: output directory. kind: the command, e.g. ``"export-bop"``.
        marker: file name(s), relative to ``path``, whose presence marks the directory as ours.
        write_marker: write :data:`MARKER` into a directory that lacks it.
        create: create the directory (and marker); False only checks (call it before slow work).
    Returns:
        True if ``path`` already held output of ``kind`` (the caller resumes or rewrites it).
    Raises:
        OutputError: ``path`` is a file, is not writable, or is a non-empty directory not written by
            ``kind``. Nothing is written in that case.
    """
    path = Path(path)
    markers = (marker,) if isinstance(marker, str) else tuple(marker)
    if path.exists() and not path.is_dir():
        raise OutputError(f"{path}: exists and is not a directory")
    ours = False
    if path.is_dir() and any(path.iterdir()):
        ours = any((path / m).exists() for m in markers)
        if not ours:
            try:
                ours = json.loads((path / MARKER).read_text()).get("kind") == kind
            except (OSError, ValueError, AttributeError):
                ours = False
        if not ours:
            raise OutputError(
                f"{path}: directory is not empty and was not written by `sixdpose {kind}`; "
                "choose a new or empty output directory (nothing was written)"
            )
    _check_writable(path)
    if not create:
        return ours
    path.mkdir(parents=True, exist_ok=True)
    if write_marker and not (path / MARKER).exists():
        atomic_write_json(path / MARKER, {"kind": kind})
    return ours


def claim_output_file(path: str | os.PathLike, first_line: str) -> bool:
    """Check that file ``path`` may be (over)written: it does not exist, or it is a file of ours,
    recognised by its first line ``first_line`` (for example a CSV header).

    Returns:
        True if an earlier output is going to be replaced.
    Raises:
        OutputError: ``path`` is a directory, is not writable, or is a file written by something else.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"{path}: is a directory; expected a file name")
    if path.exists():
        try:
            with open(path, encoding="utf-8", errors="replace") as f:
                head = f.readline().rstrip("\r\n")
        except OSError as e:
            raise OutputError(f"{path}: cannot read the existing file ({e})") from None
        if head != first_line:
            raise OutputError(f"{path}: exists and is not an output of sixdpose; choose another file name "
                              "(nothing was written)")
        if not os.access(path, os.W_OK):
            raise OutputError(f"{path}: file is not writable")
        return True
    _check_writable(path)
    return False
