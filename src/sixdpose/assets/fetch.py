"""``sixdpose fetch-ycb``: download the official per-object ``<name>_google_16k.tgz`` archives.

Each archive is downloaded to a temporary file, its size checked against ``Content-Length``, opened
and checked for the expected files, unpacked into a temporary directory and only then moved into
place; a failed or partial download never leaves anything behind. ``objects.csv`` (masses, roles,
symmetries; shipped with the package) is written for the objects present.
"""

from __future__ import annotations

import csv
import io
import os
import shutil
import tarfile
import tempfile
import urllib.error
import urllib.request
import zlib
from pathlib import Path

from ..fileio import atomic_write_text, claim_output_dir
from .ycb import MESH_SUBDIR, AssetError

#: Official YCB object-set download location (``<base>/<name>_google_16k.tgz``).
DEFAULT_BASE_URL = "http://ycb-benchmarks.s3-website-us-east-1.amazonaws.com/data/google"
_CATALOGUE = Path(__file__).with_name("objects.csv")
REQUIRED_FILES = ("textured.obj", "textured.mtl", "texture_map.png")


def catalogue_rows() -> list[dict]:
    """Rows of the packaged catalogue (``name, mass_kg, role, symmetric``) for the 46 YCB objects."""
    with open(_CATALOGUE, newline="") as f:
        return list(csv.DictReader(f))


def _download(url: str, dst: Path, timeout: float, progress) -> None:
    try:
        with urllib.request.urlopen(url, timeout=timeout) as r, open(dst, "wb") as f:
            expected = r.headers.get("Content-Length")
            n = 0
            while True:
                chunk = r.read(1 << 20)
                if not chunk:
                    break
                f.write(chunk)
                n += len(chunk)
                if progress:
                    progress(len(chunk))
    except urllib.error.HTTPError as e:
        raise AssetError(f"{url}: HTTP {e.code} {e.reason}") from None
    except (urllib.error.URLError, OSError) as e:
        raise AssetError(f"{url}: download failed ({getattr(e, 'reason', e)})") from None
    if expected is not None and int(expected) != n:
        raise AssetError(f"{url}: incomplete download ({n} of {expected} bytes)")


def _unpack(archive: Path, name: str, stage: Path, url: str) -> Path:
    try:
        with tarfile.open(archive, "r:gz") as tf:
            tf.extractall(stage, filter="data")
    except (tarfile.TarError, EOFError, OSError, zlib.error) as e:
        raise AssetError(f"{url}: corrupt archive ({e})") from None
    mesh_dir = stage / name / MESH_SUBDIR
    missing = [f for f in REQUIRED_FILES if not (mesh_dir / f).is_file()]
    if missing:
        raise AssetError(f"{url}: archive lacks {name}/{MESH_SUBDIR}/{', '.join(missing)}")
    tex = mesh_dir / "texture_map.png"
    if tex.read_bytes()[:8] != b"\x89PNG\r\n\x1a\n":
        # Drake's VTK renderer reads PNG textures only; convert if the archive holds another format
        from PIL import Image

        with Image.open(tex) as im:
            buf = io.BytesIO()
            im.convert("RGB").save(buf, format="PNG")
        tex.write_bytes(buf.getvalue())
    return stage / name


def fetch_ycb(to: str | os.PathLike, objects: list[str] | None = None, base_url: str = DEFAULT_BASE_URL,
              timeout: float = 60.0, overwrite: bool = False, progress: bool = True) -> list[str]:
    """Download and unpack YCB objects into ``to`` (official layout) and write ``to/objects.csv``.

    Args:
        to: destination asset directory (created).
        objects: names to fetch (default: all 46 of the catalogue).
        base_url: where ``<name>_google_16k.tgz`` archives live.
        overwrite: re-download objects already present.
    Returns:
        names fetched in this call.
    Raises:
        AssetError: unknown object name, HTTP or network error, incomplete or corrupt archive. Objects
        fetched before the failure stay (each is complete); nothing partial is left.
    """
    rows = {r["name"]: r for r in catalogue_rows()}
    names = list(rows) if not objects else list(objects)
    unknown = [n for n in names if n not in rows]
    if unknown:
        raise AssetError(f"unknown YCB object(s): {', '.join(unknown)}")
    to = Path(to)
    claim_output_dir(to, "fetch-ycb", marker="objects.csv")
    fetched = []
    from tqdm import tqdm

    bar = tqdm(total=len(names), unit="obj", desc="fetch-ycb", disable=not progress)
    try:
        for name in names:
            final = to / name
            if final.is_dir() and all((final / MESH_SUBDIR / f).is_file() for f in REQUIRED_FILES) and not overwrite:
                bar.update(1)
                continue
            url = f"{base_url.rstrip('/')}/{name}_google_16k.tgz"
            with tempfile.TemporaryDirectory(dir=to, prefix=".fetch-") as tmp:
                tmp = Path(tmp)
                archive = tmp / "archive.tgz"
                _download(url, archive, timeout, None)
                src = _unpack(archive, name, tmp / "x", url)
                if final.exists():
                    shutil.rmtree(final)
                os.replace(src, final)
            fetched.append(name)
            bar.update(1)
    finally:
        bar.close()
        _write_catalogue(to, rows)
    return fetched


def _write_catalogue(to: Path, rows: dict) -> None:
    present = [n for n in rows if (to / n / MESH_SUBDIR / "textured.obj").is_file()]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=["name", "mass_kg", "role", "symmetric"], lineterminator="\n")
    w.writeheader()
    for n in present:
        w.writerow(rows[n])
    atomic_write_text(to / "objects.csv", buf.getvalue())
    from .ycb import load_catalog

    load_catalog.cache_clear()
