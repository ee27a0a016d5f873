"""The one training engine (sixdpose.training) under every network's task: an interrupted run resumes to
exactly the uninterrupted result, the time budget, the run status and data fingerprint, resume hygiene."""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")
sys.path.insert(0, str(Path(__file__).parent))

from sixdpose.cli import main  # noqa: E402
from sixdpose.training import TrainingError, read_metrics, read_status  # noqa: E402
from sixdpose.training.rundir import repair_metrics  # noqa: E402
from test_pose import fake_pose_run, write_pose_dataset  # noqa: E402

SRC = Path(__file__).resolve().parents[1] / "src"
torch.set_num_threads(1)


class Interrupt(Exception):
    """Stands for a kill in the middle of an epoch."""


class Lines(logging.Handler):
    """Collects the messages of the ``sixdpose`` loggers at WARNING and above."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.lines: list[str] = []

    def emit(self, record):
        self.lines.append(record.getMessage())


@pytest.fixture
def warnings():
    h = Lines()
    logger = logging.getLogger("sixdpose")
    logger.addHandler(h)
    try:
        yield h.lines
    finally:
        logger.removeHandler(h)


@pytest.fixture(scope="module")
def pose_ds(tmp_path_factory) -> Path:
    return write_pose_dataset(tmp_path_factory.mktemp("pose") / "ds")


@pytest.fixture(scope="module")
def toy(tmp_path_factory) -> Path:
    from sixdpose.segmentation.toydata import make_toy_dataset

    return make_toy_dataset(tmp_path_factory.mktemp("toy") / "toy", n_scenes=2, views=2, seed=1)


@pytest.fixture(scope="module")
def pose_run(tmp_path_factory) -> Path:
    from sixdpose.pose.config import profile_config

    return fake_pose_run(tmp_path_factory.mktemp("fake") / "pose", profile_config("smoke"))


def _trainer(task: str, pose_ds, toy, pose_run):
    """``(train(run_dir, **kw), training data, overrides of a tiny 2-epoch run)`` of a task."""
    if task == "pose":
        from sixdpose.pose.train import train_pose

        return (lambda run, **kw: train_pose(pose_ds, run, **kw)), dict(epochs=2, repeat=2, batch_size=2)
    if task == "refiner":
        from sixdpose.pose.train import train_refiner

        return (lambda run, **kw: train_refiner(pose_run, pose_ds, run, **kw)), dict(epochs=2, repeat=2, batch_size=2)
    from sixdpose.segmentation.train import train

    return (lambda run, **kw: train(toy, run, **kw)), dict(epochs=2, max_steps_per_epoch=2, val_fraction=0.0)


def _checkpoint(path: Path) -> dict:
    return torch.load(path, map_location="cpu", weights_only=True)


def _assert_same_state(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:
        assert torch.equal(a[k], b[k]), k


def _rows(run: Path) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "seconds"} for r in read_metrics(run)]


def _interrupt_at(step: int):
    def cb(epoch, global_step):
        if global_step == step:
            raise Interrupt(f"stopped at step {step}")

    return cb


@pytest.mark.parametrize("task", ["pose", "refiner", "segmentation"])
def test_interrupted_run_resumes_to_the_uninterrupted_result(task, pose_ds, toy, pose_run, tmp_path, warnings):
    """Killed in the middle of epoch 2 (only epoch 1 is checkpointed), the unfinished run is usable with one
    warning line, and --resume ends bit for bit where the uninterrupted run does (weights, optimiser, metrics)."""
    train, ov = _trainer(task, pose_ds, toy, pose_run)
    ref = tmp_path / "ref"
    s = train(ref, profile="smoke", progress=False, **ov)
    assert s["epochs"] == 2 and not s["stopped_early"]
    steps_per_epoch = s["steps"] // 2
    assert read_status(ref)["finished"] is True and read_status(ref)["epoch"] == 2

    run = tmp_path / "run"
    with pytest.raises(Interrupt):
        train(run, profile="smoke", progress=False, after_step=_interrupt_at(steps_per_epoch + 1), **ov)
    assert _checkpoint(run / "last.pt")["epoch"] == 1 and not (run / "model.pt").exists()
    st = read_status(run)
    assert st["finished"] is False and st["epoch"] == 1 and st["epochs"] == 2

    # the unfinished run is used through its last.pt, with one warning line naming its epoch
    warnings.clear()
    if task == "segmentation":
        assert main(["segment", "--data", str(toy), "--ckpt", str(run), "--out", str(tmp_path / "pred"),
                     "--no-progress"]) == 0
    else:
        argv = ["predict-pose", "--data", str(pose_ds), "--out", str(tmp_path / "r.csv"), "--no-progress"]
        argv += ["--pose", str(run)] if task == "pose" else ["--pose", str(pose_run), "--refiner", str(run)]
        assert main(argv) == 0
    unfinished = [w for w in warnings if "unfinished run" in w]
    assert len(unfinished) == 1 and "epoch 1 of 2" in unfinished[0] and str(run) in unfinished[0], warnings
    if task == "pose":  # a refiner trained on the unfinished main network: the same one line
        warnings.clear()
        assert main(["train-refiner", "--pose", str(run), "--data", str(pose_ds), "--out", str(tmp_path / "refiner"),
                     "--profile", "smoke", "--set", "epochs=1", "--set", "repeat=1", "--no-progress"]) == 0
        assert sum("unfinished run" in w for w in warnings) == 1, warnings

    s = train(run, resume=True, progress=False)
    assert s["start_epoch"] == 1 and s["epochs"] == 2 and s["steps"] == steps_per_epoch
    a, b = _checkpoint(ref / "last.pt"), _checkpoint(run / "last.pt")
    assert a["global_step"] == b["global_step"] == 2 * steps_per_epoch
    _assert_same_state(a["model"], b["model"])
    _assert_same_state(_checkpoint(ref / "model.pt")["model"], _checkpoint(run / "model.pt")["model"])
    for k in a["optimizer"]["state"]:
        _assert_same_state(a["optimizer"]["state"][k], b["optimizer"]["state"][k])
    assert _rows(run) == _rows(ref)
    assert read_status(run)["finished"] is True


def test_time_budget_ends_a_segmentation_run(toy, tmp_path):
    """The time budget (formerly pose-only) stops any task after the step that spends it, with a final model."""
    from sixdpose.segmentation.train import train

    s = train(toy, tmp_path / "r", profile="smoke", progress=False, epochs=3, max_steps_per_epoch=2, val_fraction=0.0,
              time_budget=1e-6)
    assert s["stopped_early"] and s["epochs"] == 1 and s["steps"] == 1
    assert _checkpoint(tmp_path / "r" / "model.pt")["epoch"] == 1
    assert read_status(tmp_path / "r")["finished"] is True
    assert {r["epoch"] for r in read_metrics(tmp_path / "r")} == {0}


def test_resume_on_other_data_is_refused(pose_ds, tmp_path, capsys):
    from sixdpose.pose.train import train_pose

    run = tmp_path / "run"
    with pytest.raises(Interrupt):
        train_pose(pose_ds, run, profile="smoke", progress=False, epochs=2, repeat=1, after_step=_interrupt_at(2))
    other = write_pose_dataset(tmp_path / "other", seed=3)
    with pytest.raises(TrainingError, match="trained on .*, not on "):
        train_pose(other, run, resume=True, progress=False)
    assert main(["train-pose", "--data", str(other), "--out", str(run), "--resume", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(pose_ds) in err[0] and str(other) in err[0], err
    assert _checkpoint(run / "last.pt")["epoch"] == 1  # untouched
    # a copy of the same data elsewhere is the same data
    import shutil

    copy = Path(shutil.copytree(pose_ds, tmp_path / "copy"))
    s = train_pose(copy, run, resume=True, progress=False)
    assert s["start_epoch"] == 1 and s["epochs"] == 2


def test_resume_removes_stale_temporaries_and_repairs_metrics(pose_ds, tmp_path, warnings):
    """What kill -9 leaves behind: a temporary checkpoint of an interrupted save, a metrics.csv ending in
    NUL bytes after a half line. --resume removes the one and cuts the other, with warning lines."""
    from sixdpose.pose.train import train_pose

    ov = dict(epochs=2, repeat=1, batch_size=2)
    ref = tmp_path / "ref"
    train_pose(pose_ds, ref, profile="smoke", progress=False, **ov)
    run = tmp_path / "run"
    with pytest.raises(Interrupt):
        train_pose(pose_ds, run, profile="smoke", progress=False, after_step=_interrupt_at(3), **ov)
    stale = [run / f".last.pt.tmp{os.getpid() + 1}.pt", run / ".status.json.tmp77.json"]
    for p in stale:
        p.write_bytes(b"PK\x03\x04 half a zip")
    with open(run / "metrics.csv", "ab") as f:
        f.write(b"1,3,0.01,0.12")  # half a row of epoch 2 ...
        f.write(b"\0" * 64)  # ... and the zeroed block the file system allocated
    with pytest.raises(Exception):  # noqa: B017 - csv refuses the NUL bytes: the file really is broken
        read_metrics(run)
    warnings.clear()
    train_pose(pose_ds, run, resume=True, progress=False)
    assert not any(p.exists() for p in stale)
    assert sum("stale temporary" in w for w in warnings) == 1
    assert sum("cut by a crash" in w for w in warnings) == 1
    assert _rows(run) == _rows(ref)
    _assert_same_state(_checkpoint(ref / "model.pt")["model"], _checkpoint(run / "model.pt")["model"])


@pytest.mark.parametrize("tail,kept", [(b"", b""), (b"2,9,0.1", b""), (b"\0\0", b""),
                                       (b"1,9,0.1,0.5,,1.0\n\0\0\0", b"1,9,0.1,0.5,,1.0\n")])
def test_repair_metrics_keeps_complete_lines(tmp_path, tail, kept):
    path = tmp_path / "metrics.csv"
    good = b"epoch,step,lr,loss,val_add,seconds\n0,1,0.01,0.5,,1.0\n"
    path.write_bytes(good + tail)
    assert repair_metrics(path) is (tail != kept)
    assert path.read_bytes() == good + kept
    path.write_bytes(b"epoch,st\0\0")
    assert repair_metrics(path) and not path.exists()  # nothing complete: the file goes, resume rewrites it


def test_old_flat_configs_still_load(tmp_path):
    """Schedule fields moved to TrainSchedule keep their flat keys: saved configs of older runs lacking the
    new fields (max_steps_per_epoch for pose, warmup_steps/time_budget for segmentation) load."""
    from sixdpose.pose.config import PoseConfig, RefinerConfig, profile_config
    from sixdpose.segmentation.config import SegConfig
    from sixdpose.segmentation.config import profile_config as seg_profile
    from sixdpose.training import TrainSchedule

    for cls, drop in ((PoseConfig, "max_steps_per_epoch"), (RefinerConfig, "max_steps_per_epoch"),
                      (SegConfig, "warmup_steps"), (SegConfig, "time_budget")):
        assert issubclass(cls, TrainSchedule)
        d = cls().to_dict()
        del d[drop]
        (tmp_path / "c.json").write_text(json.dumps(d))
        assert cls.load(tmp_path / "c.json") == cls()
    assert profile_config("cpu", {"epochs": 6, "time_budget": 0}).time_budget == 0
    assert seg_profile("smoke", lr=1e-4, time_budget=60).lr == 1e-4
    assert (PoseConfig().lr, RefinerConfig().lr, SegConfig().lr_gamma, SegConfig().grad_clip) == (1e-4, 1e-3, 0.1, 10.0)


def test_learning_rate_is_warmup_times_step_decay():
    from sixdpose.pose.config import profile_config
    from sixdpose.training import learning_rate

    c = profile_config("cpu")  # lr 1e-3, 200 warm-up steps, x0.6 every 2 epochs
    assert learning_rate(c, 0, 0) == pytest.approx(1e-6)
    assert learning_rate(c, 0, 100) == pytest.approx(1e-3 * 1000 ** -0.5)
    assert learning_rate(c, 1, 200) == 1e-3
    assert learning_rate(c, 4, 5000) == pytest.approx(1e-3 * 0.36)


@pytest.mark.slow
def test_sigkill_then_resume_equals_uninterrupted(pose_ds, tmp_path):
    """A real kill -9 of `sixdpose train-pose` after a few epochs; --resume to one more epoch gives the run
    that trained that many epochs in one go."""
    env = dict(os.environ, PYTHONPATH=str(SRC), OMP_NUM_THREADS="1")
    run = tmp_path / "run"
    base = [sys.executable, "-m", "sixdpose.cli", "train-pose", "--data", str(pose_ds), "--no-progress",
            "--profile", "smoke", "--set", "repeat=1", "--set", "batch_size=1"]
    p = subprocess.Popen(base + ["--out", str(run), "--set", "epochs=2000"], env=env, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE)
    try:
        deadline = time.time() + 120
        while time.time() < deadline and (read_status(run) or {}).get("epoch", 0) < 2:
            time.sleep(0.02)
        os.kill(p.pid, signal.SIGKILL)
    finally:
        p.wait()
    assert p.returncode == -signal.SIGKILL
    assert not (run / "model.pt").exists()
    done = _checkpoint(run / "last.pt")["epoch"]
    assert done >= 2
    r = subprocess.run(base + ["--out", str(run), "--resume", "--epochs", str(done + 1)], env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    ref = tmp_path / "ref"
    r = subprocess.run(base + ["--out", str(ref), "--epochs", str(done + 1)], env=env, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    _assert_same_state(_checkpoint(ref / "model.pt")["model"], _checkpoint(run / "model.pt")["model"])
    assert _rows(run) == _rows(ref)
    assert not [q for q in run.iterdir() if ".tmp" in q.name]


@pytest.mark.slow
def test_rank0_setup_error_reaches_every_rank(pose_ds, tmp_path):
    """Under torchrun a rank-0 setup error (here: the run directory already holds a run) ends every rank
    with the error instead of leaving the others waiting at a barrier."""
    import shutil

    torchrun = Path(sys.executable).with_name("torchrun")
    if not torchrun.exists() and not shutil.which("torchrun"):
        pytest.skip("torchrun not installed")
    run = tmp_path / "busy"
    run.mkdir()
    (run / ".sixdpose.json").write_text('{"kind": "train-pose"}')
    (run / "config.json").write_text("{}")
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(SRC))
    p = subprocess.run([str(torchrun if torchrun.exists() else "torchrun"), "--nproc_per_node", "2", "--master_port",
                        "29531", "-m", "sixdpose.cli", "train-pose", "--data", str(pose_ds), "--out", str(run),
                        "--profile", "smoke", "--no-progress"], env=env, capture_output=True, text=True, timeout=120)
    assert p.returncode != 0
    assert p.stderr.count("already holds a run") >= 2, p.stderr[-3000:]  # rank 0's own and rank 1's copy


# ------------------------------------------------------------------------------------------------
# a run directory whose files were damaged: one line, never a traceback
# ------------------------------------------------------------------------------------------------
def _damage(path: Path, how: str) -> None:
    text = path.read_text()
    if how == "truncate":
        path.write_text(text[: len(text) // 2])
    elif how == "swap-type":  # every value of the first level becomes a list
        d = json.loads(text)
        path.write_text(json.dumps({k: [v] for k, v in d.items()}))
    elif how == "remove-key":
        d = json.loads(text)
        d.pop(next(iter(d)))
        path.write_text(json.dumps(d))


@pytest.mark.parametrize("name, how", [("config.json", "truncate"), ("config.json", "swap-type"),
                                       ("status.json", "truncate"), ("status.json", "swap-type"),
                                       ("status.json", "remove-key"), ("last.pt", "bytes"), ("metrics.csv", "bytes")])
def test_a_damaged_run_directory_is_one_line(pose_ds, tmp_path, capsys, name, how):
    """Resume and prediction on a run whose file ``name`` was damaged: exit 2 and one line naming the
    file, or (status.json, metrics.csv: records the run can rebuild) a resume that goes on. (A key
    missing from config.json takes its default: configs of older versions lack newer fields.)"""
    from sixdpose.pose.train import train_pose

    run = tmp_path / "run"
    with pytest.raises(Interrupt):
        train_pose(pose_ds, run, profile="smoke", progress=False, epochs=2, repeat=1, after_step=_interrupt_at(2))
    target = run / name
    if how == "bytes":
        target.write_bytes(target.read_bytes()[: max(1, target.stat().st_size // 3)] + b"\0\0garbage")
    else:
        _damage(target, how)
    capsys.readouterr()
    rc = main(["train-pose", "--data", str(pose_ds), "--out", str(run), "--resume", "--no-progress"])
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    if name in ("status.json", "metrics.csv"):  # records the run can rebuild: it resumes and finishes
        assert rc == 0, err
        assert _checkpoint(run / "model.pt")["epoch"] == 2
        assert json.loads((run / "status.json").read_text())["finished"] is True
    else:
        lines = [ln for ln in err.strip().splitlines() if ln.startswith("sixdpose")]
        assert rc == 2 and len(lines) == 1 and name in lines[0], err


def test_weight_average_is_the_final_model_and_resumes(pose_ds, tmp_path):
    """ema_decay > 0: model.pt holds the averaged weights (not the last step's), last.pt keeps both, and a run
    killed in its second epoch resumes to the same averaged model as the uninterrupted one."""
    from sixdpose.pose.train import train_pose

    ov = dict(epochs=2, repeat=2, batch_size=2, ema_decay=0.8)
    ref = tmp_path / "ref"
    s = train_pose(pose_ds, ref, profile="smoke", progress=False, **ov)
    last, final = _checkpoint(ref / "last.pt"), _checkpoint(ref / "model.pt")
    _assert_same_state(final["model"], last["ema"])
    params = [k for k, v in last["model"].items() if v.is_floating_point() and "weight" in k]
    assert params and any(not torch.equal(final["model"][k], last["model"][k]) for k in params)
    run = tmp_path / "run"
    with pytest.raises(Interrupt):
        train_pose(pose_ds, run, profile="smoke", progress=False, after_step=_interrupt_at(s["steps"] // 2 + 1), **ov)
    train_pose(pose_ds, run, resume=True, progress=False)
    _assert_same_state(_checkpoint(ref / "model.pt")["model"], _checkpoint(run / "model.pt")["model"])
    # without it the final weights are the last step's
    plain = tmp_path / "plain"
    train_pose(pose_ds, plain, profile="smoke", progress=False, **dict(ov, ema_decay=0.0))
    assert "ema" not in _checkpoint(plain / "last.pt")
    _assert_same_state(_checkpoint(plain / "model.pt")["model"], _checkpoint(plain / "last.pt")["model"])
