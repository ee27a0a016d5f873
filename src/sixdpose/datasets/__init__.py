"""Dataset readers: the paper's synthetic layout and BOP, behind one interface
(:class:`~sixdpose.datasets.base.DatasetReader`), opened by :func:`~sixdpose.datasets.readers.open_dataset`
(:mod:`.readers`, above :mod:`.base`, :mod:`.synthetic` and :mod:`.bop`); the synthetic layout's writer
(:mod:`.layout`) and the PLY model files (:mod:`.ply`)."""

from .base import DatasetError, DatasetReader, Instance, ObjectModel, Sample, collate_samples
from .readers import as_reader, open_dataset

__all__ = [
    "DatasetError",
    "DatasetReader",
    "Instance",
    "ObjectModel",
    "Sample",
    "as_reader",
    "collate_samples",
    "open_dataset",
]
