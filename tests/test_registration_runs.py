"""``register`` as a process: repeatable results (seed, workers, load), workers that die with their
parent, a quiet Ctrl-C, numeric warnings recorded as row reasons (and ``generate``'s workers too)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from sixdpose.cli import main
from test_reg_helpers import YCBV, results_without_time, write_synthetic_dataset

REPO = Path(__file__).resolve().parents[1]
needs_ycbv = pytest.mark.skipif(not YCBV.is_dir(), reason="shared/data/ycbv_sample not available")


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO / "src"), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def _sigint_ignored(pid: int) -> bool:
    """Whether process ``pid`` ignores SIGINT (bit 2 of the SigIgn mask of /proc/PID/status; False once gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("SigIgn:"):
                return bool(int(line.split()[1], 16) & (1 << (signal.SIGINT - 1)))
    except OSError:
        pass
    return False


def _session(sid: int) -> list[tuple[int, str]]:
    """``(pid, cmdline)`` of every live (not zombie) process of session ``sid``."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()  # state, ppid, pgrp, session, ...
        if int(fields[3]) == sid and fields[0] not in ("Z", "X"):
            out.append((int(d.name), cmd))
    return out


def _cpu_seconds(pid: int) -> float:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return 0.0
    f = stat[stat.rindex(")") + 2:].split()
    return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")


def _wait_for_busy_workers(proc: subprocess.Popen, n: int, cpu_s: float, timeout: float = 120.0) -> list[int]:
    """Wait until ``proc`` has ``n`` pool workers that each used ``cpu_s`` CPU seconds; their pids."""
    deadline = time.time() + timeout
    while True:
        assert proc.poll() is None, "the command ended before its workers were busy"
        assert time.time() < deadline, "the workers did not start"
        workers = [pid for pid, cmd in _session(proc.pid) if pid != proc.pid and "multiprocessing-fork" in cmd
                   and "resource_tracker" not in cmd]
        if len(workers) >= n and all(_cpu_seconds(p) >= cpu_s for p in workers):
            return workers
        time.sleep(0.1)


def _assert_session_ends(sid: int, within: float = 5.0) -> None:
    deadline = time.time() + within
    while (left := _session(sid)) and time.time() < deadline:
        time.sleep(0.1)
    assert not left, f"still running {within} s after: {left}"


def _assert_workers_die_with_their_parent(cmd: list[str], cpu_s: float, timeout: float = 120.0) -> None:
    """Start ``cmd`` (a command with 2 pool workers) in its own session, SIGKILL the parent alone once both
    workers used ``cpu_s`` CPU seconds (within ``timeout`` s), and check that the whole session ends within
    5 s and that nothing printed a traceback."""
    proc = subprocess.Popen(cmd, env=_env(), start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        _wait_for_busy_workers(proc, 2, cpu_s=cpu_s, timeout=timeout)
        os.kill(proc.pid, signal.SIGKILL)  # the parent alone
        proc.wait()
        _assert_session_ends(proc.pid, within=5.0)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert b"Traceback" not in proc.stderr.read()


@pytest.fixture(scope="module")
def syn(tmp_path_factory):
    return write_synthetic_dataset(tmp_path_factory.mktemp("syn") / "d", n_images=3)


# ------------------------------------------------------------------------------------------------
# repeatability
# ------------------------------------------------------------------------------------------------
@needs_ycbv
@pytest.mark.slow
@pytest.mark.parametrize("method", ["ransac", "fgr", "super4pcs"])
def test_same_seed_same_results_any_workers_any_load(method, tmp_path):
    """Same seed and arguments: the same CSV (times aside) with 1 worker on an idle CPU and with 2
    workers while two busy loops load the CPU; the seed is recorded beside the CSV."""
    args = ["register", "--data", str(YCBV), "--split", "train_real", "--method", method, "--icp", "--stride", "20",
            "--seed", "7", "--no-progress"]
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert main([*args, "--workers", "1", "--out", str(a)]) == 0
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        assert main([*args, "--workers", "2", "--out", str(b)]) == 0
    finally:
        for p in busy:
            p.kill()
            p.wait()
    rows_a = results_without_time(a)
    assert len(rows_a) == 1 + 7  # header + frames 0 and 20: 3 + 4 instances
    assert rows_a == results_without_time(b)
    assert yaml.safe_load((tmp_path / "a.config.yml").read_text())["seed"] == 7


def test_seed_option_and_instance_seeds(syn, tmp_path, capsys):
    from sixdpose.registration.runner import instance_seed

    s = {instance_seed(0, 0, 0, 15, k) for k in range(3)}
    s |= {instance_seed(1, 0, 0, 15, 0), instance_seed(0, 1, 0, 15, 0)}
    assert len(s) == 5 and all(0 <= x < 2**31 for x in s)
    assert instance_seed(3, 1, 2, 15, 0) == instance_seed(3, 1, 2, 15, 0)
    # the seed reaches the methods: another seed, other RANSAC draws (the same one: the same poses)
    from sixdpose.registration.presets import get_preset
    from sixdpose.registration.runner import run_registration

    runs = [run_registration(syn, "ransac", cfg=get_preset("default", seed=seed, colour_verify=False), workers=1,
                             progress=False) for seed in (0, 0, 1)]
    poses = [np.concatenate([np.r_[r.R.ravel(), r.t] for r in rows]) for rows in runs]
    assert np.array_equal(poses[0], poses[1]) and not np.array_equal(poses[0], poses[2])
    out = tmp_path / "r.csv"
    assert main(["register", "--data", str(syn), "--method", "ransac", "--seed", "-1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "argument --seed" in err and "out of range" in err and not out.exists()


# ------------------------------------------------------------------------------------------------
# workers die with their parent; Ctrl-C
# ------------------------------------------------------------------------------------------------
@needs_ycbv
@pytest.mark.slow
def test_register_workers_die_with_their_parent(tmp_path):
    cmd = [sys.executable, "-m", "sixdpose.cli", "register", "--data", str(YCBV), "--split", "train_real",
           "--method", "super4pcs", "--icp", "--workers", "2", "--no-progress", "--out", str(tmp_path / "r.csv")]
    _assert_workers_die_with_their_parent(cmd, cpu_s=2.0)


@needs_ycbv
@pytest.mark.slow
@pytest.mark.parametrize("worker_cpu_s", [0.3, 3.0])
def test_register_ctrl_c_is_one_line(tmp_path, worker_cpu_s):
    """SIGINT to the whole process group (a terminal's Ctrl-C) while the workers start (import) or
    register: exit 130, one line, no worker traceback, nothing left running."""
    cmd = [sys.executable, "-m", "sixdpose.cli", "register", "--data", str(YCBV), "--split", "train_real",
           "--method", "ransac", "--icp", "--workers", "2", "--no-progress", "--out", str(tmp_path / "r.csv")]
    # a terminal's Ctrl-C reaches a process whose SIGINT is at its default: reset it in the child, since a
    # test runner started in the background (or after something in this process ignored SIGINT) would
    # hand its ignored SIGINT down, and a process started with SIGINT ignored rightly keeps it ignored
    proc = subprocess.Popen(cmd, env=_env(), start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        workers = _wait_for_busy_workers(proc, 2, cpu_s=worker_cpu_s)
        for pid in workers:  # a worker ignores SIGINT (the parent alone reacts to it)
            os.kill(pid, signal.SIGINT)
        time.sleep(1.0)
        assert {pid for pid, _ in _session(proc.pid)} >= set(workers)
        # the parent ignores SIGINT while it starts the pool (sixdpose.workers.sigint_ignored): wait until
        # it handles SIGINT again (its SigIgn mask in /proc), so the Ctrl-C below is not lost to that window
        deadline = time.monotonic() + 30
        while _sigint_ignored(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _sigint_ignored(proc.pid), "the register process still ignores SIGINT 30 s after its pool started"
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        _assert_session_ends(proc.pid, within=5.0)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.strip().splitlines()[-1] == "sixdpose register: interrupted", err
    assert "wrote" not in out


@pytest.mark.drake
@pytest.mark.slow
def test_generate_workers_die_with_their_parent(tmp_path, ycb_dir):
    cmd = [sys.executable, "-m", "sixdpose.cli", "generate", "--profile", "smoke", "--scenes", "8", "--out",
           str(tmp_path / "g"), "--assets", str(ycb_dir), "--workers", "2", "--no-progress"]
    _assert_workers_die_with_their_parent(cmd, cpu_s=1.5, timeout=300)


# ------------------------------------------------------------------------------------------------
# numeric warnings are row reasons
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("fx, reason", [(0.0, "cam_K"), (1e-320, "numerical warning")])
def test_numeric_trouble_is_a_row_reason_not_stderr_noise(syn, tmp_path, capfd, fx, reason):
    """A zero focal length is refused by the reader: the image is a recorded per-image fault naming
    cam_K; a denormal one (x / fx overflows) raises numpy RuntimeWarnings inside the instance, which
    become its reason: score-0 rows. No warning on stderr either way."""
    from sixdpose.registration.runner import run_registration

    bad = tmp_path / "bad"
    shutil.copytree(syn, bad)
    gt = yaml.safe_load((bad / "gt.yml").read_text())
    gt[1]["cam_K"] = [[fx, 0.0, 79.5], [0.0, fx, 59.5], [0.0, 0.0, 1.0]]
    (bad / "gt.yml").write_text(yaml.safe_dump(gt))
    capfd.readouterr()
    failures: list = []
    rows = run_registration(bad, "ransac", icp=True, workers=1, progress=False, failures=failures)
    err = capfd.readouterr().err
    by_image = {}
    for r in rows:
        by_image.setdefault(r.im_id, []).append(r)
    if fx == 0.0:  # refused when the image is read: a recorded fault, no row
        assert 1 not in by_image and len(failures) == 1 and reason in str(failures[0]), failures
    else:
        assert by_image[1] and all(r.score == 0 and reason in r.reason for r in by_image[1])
    assert all(r.score > 0 and r.reason == "" for i in (0, 2) for r in by_image[i])
    assert "RuntimeWarning" not in err and "Warning:" not in err, err
    assert all(np.isfinite(r.R).all() and np.isfinite(r.t).all() for r in rows)


# ------------------------------------------------------------------------------------------------
# the objects' onboarding: timed apart from the images
# ------------------------------------------------------------------------------------------------
def test_onboarding_is_timed_apart_from_the_images(syn, tmp_path, capsys):
    """An object's first-use model-side data (references, colour grid, verification surface) is its
    onboarding: the first image that needs it spends it, the image's ``time`` leaves it out, a second image
    of the same object spends none, and ``register`` records the total in ``<out>.config.yml``."""
    from sixdpose.datasets.readers import open_dataset
    from sixdpose.registration import runner
    from sixdpose.registration.presets import get_preset

    cfg = get_preset("fast", verify=True)
    runner._init_worker(open_dataset(syn), "ransac", True, cfg, "gt", 0, 0.0)
    t0 = time.perf_counter()
    rows, fail, onboarded = runner.process_image(0)
    wall = time.perf_counter() - t0
    assert fail is None and len(rows) == 2 and onboarded > 0
    assert rows[0].time <= wall - onboarded + 1e-6  # charged to the onboarding, not to the image
    rows, fail, again = runner.process_image(1)
    assert again == 0.0 and rows[0].time > 0
    out = tmp_path / "r.csv"
    assert main(["register", "--data", str(syn), "--method", "ransac", "--icp", "--profile", "fast", "--workers", "1",
                 "--no-progress", "--out", str(out)]) == 0
    saved = yaml.safe_load(out.with_name("r.config.yml").read_text())
    assert saved["onboarding_s"] > 0 and saved["verify"] is True
    assert "onboarding" in capsys.readouterr().out


def test_a_stopped_run_resumes_from_its_journal(syn, tmp_path, monkeypatch, caplog):
    """A run stopped after its first image leaves ``<out>.journal``; the same command then registers only the
    other images and writes the rows an uninterrupted run writes (times aside: those of the finished images
    come from the journal), and removes the journal. Other arguments, a cut-short last line and ``--no-resume``
    start over."""
    from sixdpose.artifacts.journal import journal_path
    from sixdpose.registration import runner

    full = tmp_path / "full.csv"
    args = ["--method", "ransac", "--icp", "--profile", "fast", "--workers", "1", "--no-progress"]
    assert main(["register", "--data", str(syn), *args, "--out", str(full)]) == 0
    assert not journal_path(full).exists()

    out = tmp_path / "r.csv"
    real = runner.process_image
    calls: list[int] = []

    def stop_at_second(i):
        calls.append(i)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(i)

    monkeypatch.setattr(runner, "process_image", stop_at_second)
    assert main(["register", "--data", str(syn), *args, "--out", str(out)]) == 130  # as Ctrl-C
    assert not out.exists() and journal_path(out).is_file()
    first_journal = journal_path(out).read_text()
    assert len(first_journal.splitlines()) == 2  # the header and image 0

    calls.clear()
    monkeypatch.setattr(runner, "process_image", lambda i: (calls.append(i), real(i))[1])
    with caplog.at_level("WARNING"):
        assert main(["register", "--data", str(syn), *args, "--out", str(out)]) == 0
    assert calls == [1, 2]  # image 0 came from the journal
    assert "resuming: 1 image(s) already done" in caplog.text
    assert results_without_time(out) == results_without_time(full)
    assert not journal_path(out).exists()

    # a journal of other arguments is not used; a cut-short line is run again; --no-resume starts over
    journal_path(out).write_text(first_journal.replace('"icp": true', '"icp": false'))
    calls.clear()
    assert main(["register", "--data", str(syn), *args, "--out", str(out)]) == 0
    assert calls == [0, 1, 2]
    journal_path(out).write_text(first_journal[:-20])
    calls.clear()
    assert main(["register", "--data", str(syn), *args, "--out", str(out)]) == 0
    assert calls == [0, 1, 2] and results_without_time(out) == results_without_time(full)
    journal_path(out).write_text(first_journal)
    calls.clear()
    assert main(["register", "--data", str(syn), *args, "--no-resume", "--out", str(out)]) == 0
    assert calls == [0, 1, 2] and not journal_path(out).exists()
