"""Dataset readers: the paper's synthetic layout and BOP, behind one interface (:mod:`.base`)."""

from .base import DatasetError, Instance, ObjectModel, Sample, collate_samples, open_dataset

__all__ = ["DatasetError", "Instance", "ObjectModel", "Sample", "collate_samples", "open_dataset"]
