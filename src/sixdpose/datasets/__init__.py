"""Dataset readers: the paper's synthetic layout and BOP, behind one interface
(:class:`~sixdpose.datasets.base.DatasetReader`); the synthetic layout's writer (:mod:`.layout`) and the
PLY model files (:mod:`.ply`)."""

from .base import DatasetError, DatasetReader, Instance, ObjectModel, Sample, collate_samples
from .readers import as_reader, open_dataset

__all__ = ["DatasetError", "DatasetReader", "Instance", "ObjectModel", "Sample", "as_reader", "collate_samples", "open_dataset"]
