"""The synthetic reader: the interface later stages use (Sample / Instance / ObjectModel)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from sixdpose.datasets import DatasetError, Sample, collate_samples, open_dataset
from sixdpose.datasets.synthetic import SyntheticDataset


def test_samples(tiny_dataset, smoke_config):
    ds = open_dataset(tiny_dataset)
    assert isinstance(ds, SyntheticDataset)
    assert len(ds) == smoke_config.scenes * smoke_config.views
    s = ds[0]
    assert isinstance(s, Sample)
    assert s.rgb.shape == (480, 640, 3) and s.rgb.dtype == np.uint8
    assert s.depth.shape == (480, 640) and s.depth.dtype == np.float32
    assert s.K.shape == (3, 3) and s.instances
    for inst in s.instances:
        assert inst.mask.shape == (480, 640) and inst.mask.dtype == bool and inst.mask.sum() == inst.px_visib
        assert inst.R.shape == (3, 3) and inst.t.shape == (3,)
        assert ds.object_ids[inst.obj_id] == inst.obj_name
    assert [k[1] for k in ds.keys()] == ds.image_ids  # noqa: SIM118 (a dataset reader, not a dict)


def test_models(tiny_dataset):
    ds = open_dataset(tiny_dataset)
    m = ds.model(12)  # 006_mustard_bottle
    assert m.obj_name == "006_mustard_bottle" and not m.symmetric
    assert m.points.shape[1] == 3 and m.normals.shape == m.points.shape and m.colors.shape == m.points.shape
    extent = m.points.max(0) - m.points.min(0)
    assert 0.05 < extent.max() < 0.25  # metres
    assert extent.max() <= m.diameter <= np.linalg.norm(extent) + 1e-9
    assert ds.model(2).symmetric  # tennis ball
    with pytest.raises(DatasetError, match="obj_id 99"):
        ds.model(99)


def test_torch_dataloader(tiny_dataset):
    import torch

    ds = open_dataset(tiny_dataset)
    dl = torch.utils.data.DataLoader(ds, batch_size=2, collate_fn=collate_samples, num_workers=0)
    batch = next(iter(dl))
    assert len(batch) == 2 and all(isinstance(b, Sample) for b in batch)


def test_bad_files(tiny_dataset, tmp_path):
    d = tmp_path / "ds"
    shutil.copytree(tiny_dataset, d)
    (d / "RGB" / "0.png").write_bytes(b"not a png")
    ds = open_dataset(d)
    with pytest.raises(DatasetError, match=r"RGB/0\.png"):
        ds[0]
    (d / "depth" / "1.npy").unlink()
    with pytest.raises(DatasetError, match=r"depth/1\.npy: file not found"):
        ds.load(ds.keys()[1])
    with pytest.raises(DatasetError, match="no image 999"):
        ds.load((0, 999))
    (d / "gt.yml").write_text("{0: [unclosed")
    with pytest.raises(DatasetError, match="gt.yml: corrupt YAML"):
        open_dataset(d)
    (d / "gt.yml").unlink()
    with pytest.raises(DatasetError, match="run `sixdpose generate` again"):
        open_dataset(d)
    with pytest.raises(DatasetError, match="not found"):
        open_dataset(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DatasetError, match="not a dataset"):
        open_dataset(tmp_path / "empty")
