"""Segmentation config, split, bad-annotation handling and augmentation (fast unit tests)."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import numpy as np
import pytest
import yaml

torch = pytest.importorskip("torch")

from sixdpose.datasets.base import DatasetError, Instance, Sample  # noqa: E402
from sixdpose.segmentation.config import PROFILES, SegConfig, profile_config  # noqa: E402

SHARED = Path(os.environ.get("SIXDPOSE_SHARED", Path(__file__).resolve().parents[1] / ".." / "shared"))


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    from sixdpose.segmentation.toydata import make_toy_dataset

    return make_toy_dataset(tmp_path_factory.mktemp("toy") / "toy", n_scenes=4, views=5, seed=3)


# -- config -----------------------------------------------------------------------------------
def test_paper_profile_follows_section_iv_a():
    c = PROFILES["paper"]
    assert c.backbone == "resnet50" and c.pretrained and c.trainable_layers == 5  # no frozen layers
    assert (c.lr, c.lr_step_epochs, c.lr_gamma, c.epochs) == (1e-3, 30, 0.1, 100)
    assert c.val_fraction == pytest.approx(0.1)
    assert (c.fpn_channels, c.box_head_dim, c.mask_head_channels) == (256, 1024, 256)  # torchvision defaults


def test_config_roundtrip_and_validation(tmp_path):
    c = profile_config("smoke", epochs=3)
    c.save(tmp_path / "c.json")
    assert SegConfig.load(tmp_path / "c.json") == c
    with pytest.raises(ValueError, match="unknown config field"):
        SegConfig.from_dict({**c.to_dict(), "bogus": 1})
    with pytest.raises(ValueError, match="backbone"):
        profile_config("smoke", backbone="vgg")
    with pytest.raises(ValueError, match="val_fraction"):
        profile_config("smoke", val_fraction=1.0)
    with pytest.raises(ValueError, match="unknown profile"):
        profile_config("huge")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(ValueError, match="corrupt config"):
        SegConfig.load(tmp_path / "bad.json")


def test_paper_model_is_torchvision_maskrcnn_resnet50_fpn():
    """The paper config builds the same network as torchvision's maskrcnn_resnet50_fpn (no download)."""
    from torchvision.models.detection import maskrcnn_resnet50_fpn

    from sixdpose.segmentation.model import build_model

    ours, init = build_model(profile_config("paper", pretrained=False), 18)
    ref = maskrcnn_resnet50_fpn(weights=None, weights_backbone=None, num_classes=19)
    a, b = ours.state_dict(), ref.state_dict()
    assert init == "random"
    assert a.keys() == b.keys() and all(a[k].shape == b[k].shape for k in a)
    assert all(p.requires_grad for p in ours.parameters())


@pytest.mark.parametrize("backbone", ["mobilenet_v3_large", "mobilenet_v3_small"])
def test_mobilenet_backbone_feeds_the_pyramid_at_a_resnets_strides(backbone):
    """A MobileNetV3 Mask R-CNN: the pyramid's levels have the strides of a ResNet's (4 to 64), the deepest
    ``trainable_layers`` stages train and the others are frozen (the stem first), and no other MobileNet is
    accepted."""
    from sixdpose.segmentation.model import build_model

    x = torch.rand(1, 3, 96, 128)
    model, init = build_model(profile_config("smoke", backbone=backbone), 3)
    assert init == "random" and all(p.requires_grad for p in model.parameters())
    feats = model.eval().backbone(x)
    assert [tuple(f.shape[-2:]) for f in feats.values()] == [(24, 32), (12, 16), (6, 8), (3, 4), (2, 2)]
    body = model.backbone.body
    frozen, _ = build_model(profile_config("smoke", backbone=backbone, trainable_layers=2), 3)
    trains = {n for n, p in frozen.backbone.body.named_parameters() if p.requires_grad}
    deepest = max(int(n.split(".")[0]) for n, _ in body.named_parameters())
    assert any(n.startswith(f"{deepest}.") for n in trains) and not any(n.startswith("0.") for n in trains)
    assert 0 < len(trains) < len(list(body.parameters()))
    none, _ = build_model(profile_config("smoke", backbone=backbone, trainable_layers=0), 3)
    assert not any(p.requires_grad for p in none.backbone.body.parameters())
    with pytest.raises(ValueError, match="backbone"):
        profile_config("smoke", backbone="mobilenet_v2")


def test_offline_pretrained_falls_back_with_one_line(monkeypatch, tmp_path, caplog):
    from sixdpose.segmentation.model import build_model

    monkeypatch.setenv("TORCH_HOME", str(tmp_path))  # empty cache: must not download
    import torch.hub

    monkeypatch.setattr(torch.hub, "load_state_dict_from_url", lambda *a, **k: pytest.fail("download attempted"))
    with caplog.at_level(logging.WARNING, logger="sixdpose"):
        _, init = build_model(profile_config("smoke", pretrained=True), 3)
    assert init == "random"
    msgs = [r.getMessage() for r in caplog.records if "random initialisation" in r.getMessage()]
    assert len(msgs) == 1 and "\n" not in msgs[0]


# -- split --------------------------------------------------------------------------------------
def test_split_is_seeded_and_90_10(toy):
    from sixdpose.segmentation.data import make_split

    cfg = profile_config("paper")
    a, b = make_split(toy, cfg), make_split(toy, cfg)
    assert a == b
    n_test, n_train = len(a["test"]["keys"]), len(a["train"]["keys"])
    assert (n_train, n_test) == (18, 2)
    assert make_split(toy, cfg.replace(seed=1))["test"] != a["test"]
    s = make_split(toy, cfg.replace(split_by="scene", val_fraction=0.25))
    assert {k[0] for k in s["train"]["keys"]}.isdisjoint({k[0] for k in s["test"]["keys"]})
    assert len(s["test"]["keys"]) == 5
    assert make_split(toy, cfg.replace(val_fraction=0.0))["test"]["keys"] == []


def test_bop_split_uses_split_dirs():
    from sixdpose.segmentation.data import ClassMap, make_split, open_part, scan

    root = SHARED / "data" / "ycbv_sample"
    if not root.is_dir():
        pytest.skip("shared ycbv_sample not available")
    cfg = profile_config("smoke", train_split="train_real", test_split="test")
    s = make_split(root, cfg)
    assert s["train"]["split"] == "train_real" and len(s["train"]["keys"]) == 40
    assert s["test"]["keys"] == []  # no test split in the sample: said in the log, nothing held out
    ds, idx = open_part(root, s, "train")
    classes = ClassMap.from_dataset(ds)
    assert len(classes) == 21
    res = scan(ds, idx[::10], classes, cfg)
    assert set(res.missing_classes) >= {4, 6, 7}  # objects that never appear in these frames


def test_split_without_masks_is_an_error(tmp_path):
    from sixdpose.segmentation.data import ClassMap, usable_instances

    s = Sample(0, 0, np.zeros((4, 4, 3), np.uint8), None, np.eye(3), [Instance("a", 1, 0, np.eye(3), np.zeros(3))])
    with pytest.raises(DatasetError, match="has no mask"):
        usable_instances(s, ClassMap([1], ["a"]), 1)
    root = SHARED / "data" / "lmo"
    if root.is_dir():  # the LM-O sample ships no masks
        from sixdpose.segmentation.train import train

        with pytest.raises(DatasetError, match="no mask"):
            train(root, tmp_path / "r", profile="smoke", train_split="test", progress=False)


# -- bad annotations ------------------------------------------------------------------------------
@pytest.fixture()
def bad_toy(tmp_path):
    """A toy dataset with an image without annotations, an empty mask and a class never present."""
    from PIL import Image

    from sixdpose.segmentation.toydata import make_toy_dataset

    root = make_toy_dataset(tmp_path / "bad", n_scenes=1, views=4, n_classes=2, seed=5)
    gt = yaml.safe_load((root / "gt.yml").read_text())
    gt[0]["objects"] = []  # image 0: no annotation
    name = gt[1]["objects"][0]["obj_name"]
    Image.fromarray(np.zeros((480, 640), np.uint8)).save(root / "masks" / name / "1_9.png")
    gt[1]["objects"].append({**gt[1]["objects"][0], "inst": 9, "px_visib": 0})  # image 1: an empty mask
    (root / "gt.yml").write_text(yaml.safe_dump(gt))
    info = yaml.safe_load((root / "models" / "models_info.yml").read_text())
    info["077_rubiks_cube"] = {"obj_id": 7, "diameter": 0.1}  # a class without any instance
    (root / "models" / "models_info.yml").write_text(yaml.safe_dump(info))
    return root


def test_scan_skips_and_reports_bad_annotations(bad_toy, caplog):
    from sixdpose.datasets import open_dataset
    from sixdpose.segmentation.data import ClassMap, scan

    ds = open_dataset(bad_toy)
    classes = ClassMap.from_dataset(ds)
    assert classes.obj_ids == [1, 2, 7]
    with caplog.at_level(logging.INFO, logger="sixdpose"):
        res = scan(ds, list(range(len(ds))), classes, profile_config("smoke"))
    assert res.skipped_images == [[0, 0, "no annotated instance"]]
    assert res.dropped_instances == [[0, 1, gt_obj(ds, 1), 9, "empty mask"]]
    assert res.missing_classes == [7]
    assert 0 not in res.usable and set(res.usable) == {1, 2, 3}
    text = caplog.text
    assert "skipping training image scene 0 image 0" in text
    assert "empty mask" in text
    assert "7 (077_rubiks_cube)" in text


def gt_obj(ds, im):
    return ds[im].instances[-1].obj_id


def test_training_records_skips_in_split_json(bad_toy, tmp_path):
    from sixdpose.segmentation.train import train

    run = tmp_path / "run"
    train(bad_toy, run, profile="smoke", epochs=1, max_steps_per_epoch=1, val_fraction=0.0, progress=False)
    sp = json.loads((run / "split.json").read_text())
    assert sp["scan"]["skipped_images"] and sp["scan"]["dropped_instances"] and sp["scan"]["missing_classes"] == [7]
    assert sp["classes"][-1] == [7, "077_rubiks_cube"]


def test_no_usable_image_is_an_error(bad_toy):
    from sixdpose.datasets import open_dataset
    from sixdpose.segmentation.data import ClassMap, scan

    ds = open_dataset(bad_toy)
    with pytest.raises(DatasetError, match="nothing to train on"):
        scan(ds, [0], ClassMap.from_dataset(ds), profile_config("smoke"))


# -- targets and augmentation -------------------------------------------------------------------
def test_targets_and_deterministic_augmentation(toy):
    from sixdpose.datasets import open_dataset
    from sixdpose.segmentation.data import ClassMap, TrainView, augment, sample_to_target

    ds = open_dataset(toy)
    classes = ClassMap.from_dataset(ds)
    s = ds[0]
    img, t = sample_to_target(s, classes, 1)
    assert img.shape == (3, 480, 640) and img.dtype == torch.float32 and img.min() >= 0 and img.max() <= 1
    assert t["masks"].shape[0] == t["boxes"].shape[0] == t["labels"].shape[0] == len(s.instances)
    for m, b in zip(t["masks"], t["boxes"], strict=True):
        ys, xs = torch.nonzero(m, as_tuple=True)
        assert b.tolist() == [xs.min().item(), ys.min().item(), xs.max().item() + 1, ys.max().item() + 1]
    cfg = profile_config("smoke", hflip_prob=1.0, color_jitter=(0.3, 0.3, 0.3, 0.05))
    v = TrainView(ds, [0, 1], classes, cfg)
    v.set_epoch(2)
    a1, ta = v[0]
    a2, _ = v[0]
    assert torch.equal(a1, a2)  # same (seed, epoch, index) -> same draw
    v.set_epoch(3)
    assert not torch.equal(v[0][0], a1)
    flipped, tf = augment(img, t, cfg.replace(color_jitter=(0, 0, 0, 0)), torch.Generator().manual_seed(0))
    assert torch.equal(flipped, img.flip(-1)) and torch.equal(tf["masks"], t["masks"].flip(-1))
    for m, b in zip(tf["masks"], tf["boxes"], strict=True):
        ys, xs = torch.nonzero(m, as_tuple=True)
        assert b.tolist() == [xs.min().item(), ys.min().item(), xs.max().item() + 1, ys.max().item() + 1]


def test_pretrained_weights_come_from_local_cache(monkeypatch, tmp_path):
    """With the file in the torch hub cache, the backbone is initialised from it (no network)."""
    import torchvision

    from sixdpose.segmentation.model import build_model, cached_weights_path

    monkeypatch.setenv("TORCH_HOME", str(tmp_path))
    path = Path(cached_weights_path("resnet18"))
    assert path.is_relative_to(tmp_path)
    path.parent.mkdir(parents=True)
    ref = torchvision.models.resnet18().state_dict()
    torch.save(ref, path)
    model, init = build_model(profile_config("smoke", pretrained=True), 3)
    assert init == "imagenet"
    body = model.backbone.body.state_dict()
    assert torch.equal(body["conv1.weight"], ref["conv1.weight"])
    assert torch.equal(body["layer4.1.conv2.weight"], ref["layer4.1.conv2.weight"])


@pytest.mark.parametrize("backbone", ["resnet18", "mobilenet_v3_large"])
def test_compiled_backbone_gives_the_eager_detections_at_other_sizes(backbone):
    """``optimise_backbone`` swaps in a frozen TorchScript body whose pyramid equals the eager one on an image
    size and batch other than the one it was traced at, so the detections do not change."""
    import copy

    from sixdpose.segmentation.infer import optimise_backbone
    from sixdpose.segmentation.model import build_model

    cfg = profile_config("smoke", backbone=backbone, score_thresh=0.0)
    torch.manual_seed(0)
    eager, _ = build_model(cfg, 3)
    eager.eval()
    compiled = copy.deepcopy(eager)
    assert optimise_backbone(compiled, cfg)
    assert type(compiled.backbone).__name__ == "_TracedBackbone"
    assert compiled.backbone.out_channels == eager.backbone.out_channels
    x = torch.rand(2, 3, 160, 224, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        a, b = eager.backbone(x), compiled.backbone(x)
        assert list(a) == list(b)
        for k in a:
            assert a[k].shape == b[k].shape and torch.allclose(a[k], b[k], atol=1e-4)
        da, db = eager(list(x)), compiled(list(x))
    for u, v in zip(da, db, strict=True):
        assert torch.equal(u["labels"], v["labels"]) and torch.allclose(u["boxes"], v["boxes"], atol=1e-2)


def test_inference_transform_normalises_after_resizing_with_the_same_network_input():
    """The Segmenter's transform (_ResizeFirst: normalise after a shrinking resize, before an enlarging one)
    gives torchvision's input (normalise, then resize) up to float rounding, and the same image sizes."""
    import copy

    from sixdpose.segmentation.infer import _ResizeFirst
    from sixdpose.segmentation.model import build_model

    cfg = profile_config("smoke")
    model, _ = build_model(cfg, 3)
    model.eval()
    model.transform.min_size, model.transform.max_size = (100,), 1000  # 120x160 shrinks, 97x211 grows
    fast = copy.deepcopy(model.transform)
    fast.__class__ = _ResizeFirst
    g = torch.Generator().manual_seed(2)
    ims = [torch.rand(3, 120, 160, generator=g), torch.rand(3, 97, 211, generator=g)]
    with torch.no_grad():
        ref, _ = model.transform(ims)
        got, _ = fast(ims)
    assert got.image_sizes == ref.image_sizes and got.tensors.shape == ref.tensors.shape
    assert torch.allclose(got.tensors, ref.tensors, atol=1e-5) and ref.tensors.abs().max() > 1.0


def test_a_compiled_backbone_that_disagrees_is_not_used(monkeypatch, caplog):
    """When the compiled body's features differ from the eager ones, the eager body is kept, with a warning."""
    from sixdpose.segmentation.infer import optimise_backbone
    from sixdpose.segmentation.model import build_model

    cfg = profile_config("smoke")
    model, _ = build_model(cfg, 3)
    model.eval()
    eager = model.backbone

    class Off(torch.nn.Module):
        def __init__(self, m):
            super().__init__()
            self.m = m

        def forward(self, x):
            return {k: v + 1.0 for k, v in self.m(x).items()}

    real = torch.jit.optimize_for_inference
    monkeypatch.setattr(torch.jit, "optimize_for_inference", lambda m: Off(real(m)))
    with caplog.at_level(logging.WARNING, logger="sixdpose"):
        assert not optimise_backbone(model, cfg)
    assert model.backbone is eager
    assert "not compiled" in caplog.text
