"""Open a dataset directory with the reader of its layout (:func:`open_dataset`), or take a reader as it is
(:func:`as_reader`). This module sits above :mod:`.base` and the two readers (:mod:`.synthetic`,
:mod:`.bop`), so that they need not import each other.
"""

from __future__ import annotations

from pathlib import Path

from .base import DatasetError, DatasetReader


def open_dataset(path: str | Path, split: str = "test", **kwargs) -> DatasetReader:
    """Open a dataset directory, detecting its layout.

    Args:
        path: a synthetic dataset directory (has ``gt.yml``) or a BOP dataset root (has
            ``models/models_info.json``).
        split: BOP split name (ignored for the synthetic layout).
        **kwargs: passed to the reader class.
    Returns:
        A :class:`~sixdpose.datasets.base.DatasetReader`: a :class:`~sixdpose.datasets.synthetic.SyntheticDataset` or a
        :class:`~sixdpose.datasets.bop.BopDataset`.
    Raises:
        DatasetError: the directory does not exist or is neither layout.
    """
    path = Path(path)
    if not path.is_dir():
        raise DatasetError(f"{path}: dataset directory not found")
    if (path / "gt.yml").is_file() or (path / "manifest.json").is_file():
        from .synthetic import SyntheticDataset

        return SyntheticDataset(path, **kwargs)
    if (path / "models" / "models_info.json").is_file():
        from .bop import BopDataset

        return BopDataset(path, split=split, **kwargs)
    raise DatasetError(
        f"{path}: not a dataset (no gt.yml for the synthetic layout, no models/models_info.json for BOP)"
    )


def as_reader(data: str | Path | DatasetReader, split: str = "test", **kwargs) -> DatasetReader:
    """``data`` itself if it is already a :class:`~sixdpose.datasets.base.DatasetReader`, else
    :func:`open_dataset` of the path.

    Every stage entry point accepts a reader or a path through this function, so a dataset is opened
    once and a caller can hand in a reader of its own (for example one that alters images).
    """
    if isinstance(data, DatasetReader):
        if kwargs:
            raise TypeError(f"reader options {sorted(kwargs)} apply only when a path is given")
        return data
    return open_dataset(data, split=split, **kwargs)


def dataset_fingerprint(reader: DatasetReader) -> str | None:
    """sha256 (hex) identifying the images and annotations of a dataset split, cheaply: the annotation
    files that list the images and their cameras, not the image bytes.

    BOP: the split name, then per scene folder of the split (all of them, whatever subset the reader
    was opened with) its name and the bytes of ``scene_gt.json`` and ``scene_camera.json``. Synthetic
    layout: the bytes of ``gt.yml`` (images, scenes, cameras and poses). Predicted masks record it
    (``meta.json``) so that they are not used on another dataset.

    Returns:
        the hex digest, or None for a reader of another kind (nothing to fingerprint).
    """
    import hashlib

    from .bop import BopDataset
    from .synthetic import SyntheticDataset

    h = hashlib.sha256()
    if isinstance(reader, BopDataset):
        h.update(f"bop\0{reader.split}\0".encode())
        for d in sorted(p for p in reader.split_dir.iterdir() if p.is_dir() and p.name.isdigit()):
            h.update(f"{d.name}\0".encode())
            for name in ("scene_gt.json", "scene_camera.json"):
                f = d / name
                h.update(hashlib.sha256(f.read_bytes()).digest() if f.is_file() else b"-")
        return h.hexdigest()
    if isinstance(reader, SyntheticDataset):
        from . import layout

        h.update(b"synthetic\0")
        h.update((reader.root / layout.GT_FILE).read_bytes())
        return h.hexdigest()
    return None
