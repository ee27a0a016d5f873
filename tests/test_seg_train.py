"""Training mechanics: checkpoints, exact resume (also after an interruption), DDP with 2 CPU processes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")

FAST = dict(max_steps_per_epoch=2, val_fraction=0.0)


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    """A 4-image shapes dataset (synthetic layout)."""
    from sixdpose.segmentation.toydata import make_toy_dataset

    return make_toy_dataset(tmp_path_factory.mktemp("toy") / "toy", n_scenes=2, views=2, seed=1)


def _weights(path: Path) -> dict:
    return torch.load(path, map_location="cpu", weights_only=True)["model"]


def _assert_same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:
        assert torch.equal(a[k], b[k]), k


@pytest.fixture(scope="module")
def reference(toy, tmp_path_factory):
    """An uninterrupted 2-epoch run."""
    from sixdpose.segmentation.train import train

    run = tmp_path_factory.mktemp("ref") / "run"
    train(toy, run, profile="smoke", epochs=2, progress=False, **FAST)
    return run


def test_checkpoint_contents(reference):
    ck = torch.load(reference / "last.pt", map_location="cpu", weights_only=True)
    assert ck["format"] == "sixdpose-seg" and ck["epoch"] == 2
    for key in ("model", "optimizer", "scaler", "rng", "config", "classes", "global_step"):
        assert key in ck
    assert ck["global_step"] == 4  # 2 epochs of max_steps_per_epoch=2 (the LR schedule is a function of it)
    assert len(ck["rng"]) == ck["world_size"] == 1
    assert not list(reference.glob("*.tmp*"))  # atomic writes leave no temp files
    cfg = json.loads((reference / "config.json").read_text())
    assert cfg["profile"] == "smoke" and cfg["epochs"] == 2


@pytest.mark.slow
def test_resume_extends_run_exactly(toy, reference, tmp_path):
    """1 epoch, then --resume to 2 epochs == 2 epochs in one go (bitwise, on CPU)."""
    from sixdpose.segmentation.train import read_metrics, train

    run = tmp_path / "run"
    train(toy, run, profile="smoke", epochs=1, progress=False, **FAST)
    assert torch.load(run / "last.pt", weights_only=True)["epoch"] == 1
    s = train(toy, run, resume=True, epochs=2, progress=False)
    assert s["start_epoch"] == 1 and s["steps"] == 2
    _assert_same(_weights(run / "model.pt"), _weights(reference / "model.pt"))
    assert [r["epoch"] for r in read_metrics(run)] == [r["epoch"] for r in read_metrics(reference)]


@pytest.mark.slow
def test_resume_after_interruption(toy, reference, tmp_path, monkeypatch):
    """A crash in the middle of epoch 2 loses only that epoch; --resume redoes it identically."""
    from sixdpose.segmentation import data as segdata
    from sixdpose.segmentation.train import read_metrics, train

    run = tmp_path / "run"
    orig = segdata.TrainView.__getitem__
    calls = {"n": 0}

    def flaky(self, i):
        if self.epoch == 1:
            calls["n"] += 1
            if calls["n"] == 3:  # second step of epoch 2
                raise KeyboardInterrupt
        return orig(self, i)

    monkeypatch.setattr(segdata.TrainView, "__getitem__", flaky)
    with pytest.raises(KeyboardInterrupt):
        train(toy, run, profile="smoke", epochs=2, progress=False, **FAST)
    monkeypatch.setattr(segdata.TrainView, "__getitem__", orig)
    assert torch.load(run / "last.pt", weights_only=True)["epoch"] == 1
    assert not (run / "model.pt").exists()
    assert {r["epoch"] for r in read_metrics(run)} == {0}
    train(toy, run, resume=True, progress=False)
    _assert_same(_weights(run / "model.pt"), _weights(reference / "model.pt"))
    assert len(read_metrics(run)) == len(read_metrics(reference))


def test_run_dir_guards(toy, reference, tmp_path):
    """No silent overwrite of a run; nothing to resume; no config changes on resume."""
    from sixdpose.segmentation.train import TrainingError, train

    with pytest.raises(TrainingError, match="already holds a run"):
        train(toy, reference, profile="smoke", progress=False)
    with pytest.raises(TrainingError, match="nothing to resume"):
        train(toy, tmp_path / "empty", resume=True, progress=False)
    with pytest.raises(TrainingError, match="cannot change lr"):
        train(toy, reference, resume=True, lr=0.1, progress=False)
    with pytest.raises(TrainingError, match="profile 'smoke', not 'paper'"):
        train(toy, reference, resume=True, profile="paper", progress=False)


def test_cli_errors_are_one_line(toy, reference, tmp_path, capsys):
    from sixdpose.cli import main

    assert main(["train-seg", "--data", str(toy), "--out", str(reference)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sixdpose train-seg: error:") and "already holds a run" in err and "\n" not in err
    assert main(["train-seg", "--data", str(tmp_path / "nope"), "--out", str(tmp_path / "r")]) == 2
    assert "dataset directory not found" in capsys.readouterr().err


@pytest.mark.slow
def test_ddp_two_cpu_processes(toy, tmp_path):
    """torchrun with 2 gloo processes: trains, rank 0 alone writes, per-rank RNG saved, resume works."""
    run = tmp_path / "ddp"
    env = dict(os.environ, OMP_NUM_THREADS="1")
    base = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node=2",
            "-m", "sixdpose.cli", "train-seg", "--data", str(toy), "--out", str(run),
            "--max-steps-per-epoch", "1", "--threads", "1", "--no-progress", "--device", "cpu"]
    p = subprocess.run(base + ["--epochs", "1", "--val-fraction", "0"], env=env, capture_output=True, text=True,
                       timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    assert p.stdout.count("trained ") == 1, p.stdout  # summary from rank 0 only
    ck = torch.load(run / "last.pt", map_location="cpu", weights_only=True)
    assert ck["world_size"] == 2 and len(ck["rng"]) == 2 and ck["epoch"] == 1
    assert not torch.equal(ck["rng"][0]["torch"], ck["rng"][1]["torch"])
    assert json.loads((run / "run.json").read_text())["world_size"] == 2
    p = subprocess.run(base + ["--resume", "--epochs", "2"], env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    assert torch.load(run / "model.pt", map_location="cpu", weights_only=True)["epoch"] == 2


def test_diverged_loss_is_an_error(toy, tmp_path, monkeypatch):
    """A non-finite loss stops training with a clear error instead of writing a broken model."""
    from sixdpose.segmentation import data as segdata
    from sixdpose.segmentation.train import TrainingError, train

    orig = segdata.TrainView.__getitem__

    def nan_image(self, i):
        img, t = orig(self, i)
        return img * float("nan"), t

    monkeypatch.setattr(segdata.TrainView, "__getitem__", nan_image)
    with pytest.raises(TrainingError, match="training diverged"):
        train(toy, tmp_path / "r", profile="smoke", epochs=1, progress=False, **FAST)
    assert not (tmp_path / "r" / "model.pt").exists()
