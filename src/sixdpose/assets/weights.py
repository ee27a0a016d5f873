"""``sixdpose fetch-weights``: torchvision's ImageNet backbone weights, downloaded into the local torch hub cache.

The segmentation stage (:func:`sixdpose.segmentation.model.build_model`) never downloads anything: it uses
ImageNet weights only when the file is already at :func:`cached_weights_path`, the path torchvision itself
would cache them at (``torch.hub.get_dir()/checkpoints/<file name of the weights' URL>``). This module puts
the file there, the way ``torch.hub.download_url_to_file`` with ``check_hash`` would, and more:

* the URL and the checksum come from torchvision (``ResNet50_Weights.IMAGENET1K_V1.url``; the file name
  ``resnet50-<hash>.pth`` carries a prefix of the file's sha256, read with ``torch.hub.HASH_REGEX``);
* the download streams into ``<file>.part`` beside the final file; a later run resumes it with an HTTP
  ``Range`` request (and starts over when the server ignores ``Range``);
* the whole file's sha256 must start with the prefix; otherwise the part file is removed and the error
  names the file; a good file is renamed into place (``os.replace``: the cache never holds half a file);
* a file already in place with a good checksum is kept (nothing is downloaded).
"""

from __future__ import annotations

import hashlib
import http.client
import logging
import os
import re
import urllib.error
import urllib.request
from dataclasses import dataclass
from pathlib import Path

from ..constants import SEG_BACKBONES
from .ycb import AssetError

#: Backbones whose ImageNet weights the segmentation stage can start from.
BACKBONES = SEG_BACKBONES
_CHUNK = 1 << 20
_CONTENT_RANGE = re.compile(r"^bytes (\d+)-(\d+)/(\d+|\*)$")


class WeightsError(AssetError):
    """The weights cannot be fetched: server unreachable, HTTP error, interrupted download, bad checksum."""


def imagenet_weights(backbone: str):
    """torchvision's ``IMAGENET1K_V1`` weights enum member of ``backbone`` (one of :data:`BACKBONES`)."""
    from torchvision.models import (
        MobileNet_V3_Large_Weights,
        MobileNet_V3_Small_Weights,
        ResNet18_Weights,
        ResNet34_Weights,
        ResNet50_Weights,
    )

    table = {"resnet18": ResNet18_Weights, "resnet34": ResNet34_Weights, "resnet50": ResNet50_Weights,
             "mobilenet_v3_large": MobileNet_V3_Large_Weights, "mobilenet_v3_small": MobileNet_V3_Small_Weights}
    if backbone not in table:
        raise WeightsError(f"no ImageNet weights known for backbone {backbone!r} (one of {', '.join(BACKBONES)})")
    return table[backbone].IMAGENET1K_V1


@dataclass(frozen=True)
class WeightsFile:
    """Where one weights file comes from and what it must hash to.

    Attributes:
        url: download location.
        path: destination (the torch hub cache file torchvision loads).
        sha256: the expected sha256 or a prefix of it (lower-case hex).
    """

    url: str
    path: Path
    sha256: str

    @property
    def part(self) -> Path:
        """The partial download, beside :attr:`path`."""
        return self.path.with_name(self.path.name + ".part")


def cached_weights_path(backbone: str) -> Path:
    """Where torchvision's ImageNet weights of ``backbone`` live in the local torch hub cache (``$TORCH_HOME``)."""
    import torch.hub

    return Path(torch.hub.get_dir()) / "checkpoints" / os.path.basename(imagenet_weights(backbone).url)


def weights_file(backbone: str = "resnet50", url: str | None = None, sha256: str | None = None) -> WeightsFile:
    """The :class:`WeightsFile` of ``backbone``'s ImageNet weights: torchvision's URL unless ``url`` (a mirror),
    the hash prefix of torchvision's file name unless ``sha256`` (a full digest or a prefix of one)."""
    import torch.hub

    path = cached_weights_path(backbone)
    if sha256 is None:
        m = torch.hub.HASH_REGEX.search(path.name)
        if m is None or not m.group(1):
            raise WeightsError(f"{path.name}: no sha256 prefix in the file name; give one with --sha256")
        sha256 = m.group(1)
    sha256 = sha256.strip().lower()
    if not re.fullmatch(r"[0-9a-f]{8,64}", sha256):
        raise WeightsError(f"sha256 {sha256!r}: expected 8 to 64 hexadecimal digits")
    return WeightsFile(url=url or imagenet_weights(backbone).url, path=path, sha256=sha256)


def file_sha256(path: Path) -> str:
    """Hex sha256 of the file at ``path``."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(_CHUNK), b""):
            h.update(chunk)
    return h.hexdigest()


def _open(w: WeightsFile, start: int, timeout: float):
    """The HTTP response for ``w.url`` from byte ``start`` on (a ``Range`` request when ``start`` > 0), or None
    when the server says the range is past the end (the part file may hold the whole file)."""
    headers = {"User-Agent": "sixdpose fetch-weights"}
    if start:
        headers["Range"] = f"bytes={start}-"
    try:
        return urllib.request.urlopen(urllib.request.Request(w.url, headers=headers), timeout=timeout)
    except urllib.error.HTTPError as e:
        if e.code == 416 and start:
            return None
        raise WeightsError(f"{w.url}: HTTP {e.code} {e.reason}") from None
    except (urllib.error.URLError, http.client.HTTPException, OSError) as e:
        raise WeightsError(f"cannot reach {w.url} ({getattr(e, 'reason', e)}); offline? give a mirror with --url, "
                           f"or copy the file to {w.path}") from None


def _stream(w: WeightsFile, timeout: float, progress: bool) -> None:
    """Download ``w.url`` into ``w.part``: append from the part's current size when the server honours
    ``Range`` (206 from exactly that byte), else write the whole file from the start."""
    from tqdm import tqdm

    have = w.part.stat().st_size if w.part.is_file() else 0
    r = _open(w, have, timeout)
    if r is None:  # 416: nothing left to fetch; the checksum decides
        return
    m = _CONTENT_RANGE.match(r.headers.get("Content-Range", "").strip())
    if r.status == 206 and not (have and m and int(m.group(1)) == have):
        r.close()  # a range we did not ask for: start over without Range
        have = 0
        r = _open(w, 0, timeout)
    with r:
        length = r.headers.get("Content-Length")
        if have and r.status == 206:
            mode = "ab"
            size = int(m.group(3)) if m and m.group(3) != "*" else None
        else:  # the whole file (the server ignored Range, or nothing to resume)
            mode, have = "wb", 0
            size = int(length) if length is not None else None
        expected = have + int(length) if length is not None else size
        bar = tqdm(total=size, initial=have, unit="B", unit_scale=True, unit_divisor=1024, desc=w.path.name,
                   disable=not progress)
        n = have
        try:
            with open(w.part, mode) as f:
                while chunk := r.read(_CHUNK):
                    f.write(chunk)
                    n += len(chunk)
                    bar.update(len(chunk))
        except (http.client.HTTPException, OSError) as e:  # connection cut or timed out: the part file stays
            raise WeightsError(f"{w.url}: download interrupted after {n} bytes ({e}); run again to resume "
                               f"{w.part}") from None
        finally:
            bar.close()
    if expected is not None and n < expected:
        raise WeightsError(f"{w.url}: incomplete download ({n} of {expected} bytes); run again to resume {w.part}")


def fetch_weights(backbone: str = "resnet50", url: str | None = None, sha256: str | None = None,
                  timeout: float = 60.0, progress: bool = True) -> tuple[Path, bool]:
    """Download ``backbone``'s ImageNet weights into the torch hub cache (see the module docstring).

    Args:
        backbone: one of :data:`BACKBONES` (the file torchvision and the segmentation stage load).
        url: download from here instead of torchvision's URL (a mirror; tests).
        sha256: expected digest or prefix instead of the one in torchvision's file name.
        timeout: network timeout in seconds.
        progress: show a progress bar (bytes).
    Returns:
        ``(path, downloaded)``: the file in the cache, and False when it was already there with a good checksum.
    Raises:
        WeightsError: the server cannot be reached (naming the URL), an HTTP error, an interrupted or incomplete
        download (the part file stays, the next run resumes it), a checksum mismatch (the part file is
        removed; the message names the file). The cache never holds a file that failed the check.
    """
    w = weights_file(backbone, url, sha256)
    if w.path.is_file():
        if file_sha256(w.path).startswith(w.sha256):
            return w.path, False
        logging.getLogger("sixdpose").warning("%s: checksum mismatch; downloading it again", w.path)
    w.path.parent.mkdir(parents=True, exist_ok=True)
    _stream(w, timeout, progress)
    digest = file_sha256(w.part)
    if not digest.startswith(w.sha256):
        w.part.unlink()
        raise WeightsError(f"{w.path}: checksum mismatch (sha256 {digest[:16]}..., expected {w.sha256}...) of the "
                           f"download from {w.url}; the download was removed")
    os.replace(w.part, w.path)
    return w.path, True


__all__ = ["BACKBONES", "WeightsError", "WeightsFile", "cached_weights_path", "fetch_weights", "file_sha256",
           "imagenet_weights", "weights_file"]
