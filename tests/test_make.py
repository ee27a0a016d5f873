"""The graph of ``make reproduce`` (mk/profiles.mk, mk/reproduce.mk): the plan each profile prints with
``make -n`` (nothing runs), and the profile checks."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="GNU make not installed")


def _plan(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    # -B: every target out of date, so the plan is the whole graph whatever this checkout holds
    return subprocess.run(
        ["make", "-nB", "--no-print-directory", *args], cwd=REPO, capture_output=True, text=True, timeout=120, env=env
    )


def _lines(out: str, cmd: str) -> list[str]:
    return [line for line in out.splitlines() if line.startswith(f".venv/bin/sixdpose {cmd} ")]


@pytest.mark.parametrize("profile, train, seg, splits", [
    ("paper", "data/paper", "paper", ("data/test", "data/test_single")),
    ("cpu", "data/train", "cpu", ("data/test", "data/test_single")),
    ("demo", "data/demo", "smoke", ("data/demo_test", "data/demo_single")),
])
def test_the_plan_of_each_profile(profile, train, seg, splits):
    p = _plan("reproduce", f"PROFILE={profile}", "WITH_LATEX=1")
    assert p.returncode == 0, p.stderr
    out = p.stdout
    gen = {re.search(r"--out (\S+)", line).group(1) for line in _lines(out, "generate")}
    assert gen >= {train, *splits}
    assert ("data/val" in gen) == (profile in ("cpu", "paper"))
    seg_line = next(line for line in _lines(out, "train-seg") if f"--out runs/{profile}/seg" in line)
    # a new run gets the profile; an interrupted one (last.pt in this checkout) is resumed
    assert out.split(seg_line, 1)[1].lstrip().startswith((f"--profile {seg}", "--resume")) or "--resume" in seg_line
    # the held-out splits' masks, and notebook 03's predictions on the seg run's own held-out images; cpu also
    # trains the dense head's real-time segmenter (SEG_FAST_cpu) and segments the test split with it
    fast = profile == "cpu"
    assert len(_lines(out, "segment")) == 3 + fast
    fast_seg = [line for line in _lines(out, "train-seg") if "--out runs/cpu/seg_fast " in line]
    assert len(fast_seg) == fast
    if fast:
        rest = out.split(fast_seg[0], 1)[1].split("\n.venv")[0]  # its continuation line
        assert "--set backbone=mobilenet_v3_large" in rest or "--resume" in rest
        assert ".venv/bin/sixdpose segment --data data/test --seg runs/cpu/seg_fast --out runs/cpu/masks_fast/test " \
            in out
    assert f".venv/bin/sixdpose segment --data {train} --seg runs/{profile}/seg --subset test " \
        f"--out runs/{profile}/seg/pred_test --no-progress" in out
    # the synthetic-to-real branch: ycbv data, 6 networks + 2 refiners, 15 methods on real frames
    ycbv = profile in ("cpu", "paper")
    kinect = f"{splits[0]}_kinect"  # the multi-instance test split again with kinect depth (notebook 08)
    poses = [line for line in _lines(out, "register") + _lines(out, "predict-pose")
             if "ycbv_sample" not in line and kinect not in line]
    real = [
        line
        for line in _lines(out, "register") + _lines(out, "predict-pose")
        if "--data ../shared/data/ycbv_sample" in line
    ]
    evals = [line for line in _lines(out, "evaluate") if "ycbv_sample" not in line and kinect not in line]
    # 13 methods (6 hybrid, 4 learned, the dense head alone, + ICP, + ICP + verification) x 2 splits x 2 mask
    # sources, + at cpu
    # and paper the 3 hybrid rows with the paper's settings
    paper_rows = [line for line in poses if "--preset paper" in line]
    assert len(paper_rows) == (12 if ycbv else 0)
    # cpu: the dense head and + ICP on the real-time segmenter's masks (test_fast_dense, test_fast_dense_icp)
    fast_rows = [line for line in poses if "--masks runs/cpu/masks_fast/test --score-thresh 0.5" in line]
    assert len(fast_rows) == 2 * fast
    assert len(poses) == 52 + len(paper_rows) + len(fast_rows) and len(evals) == len(poses)
    # the dense head end to end (benchmarks/pose.py) at cpu and paper, on the real-time segmenter where there is one
    e2e = [line for line in out.splitlines() if line.startswith(".venv/bin/python benchmarks/pose.py ")]
    assert len(e2e) == (profile in ("cpu", "paper"))
    if e2e:
        assert f"--seg runs/{profile}/{'seg_fast' if fast else 'seg'} " in e2e[0]
    # the dense head (runs/P/pose_dense) trained once on the training data, with DENSE_<profile>'s recipe
    dense = [line for line in _lines(out, "train-pose") if f"--out runs/{profile}/pose_dense " in line]
    assert len(dense) == 1 and f"--data {train} " in dense[0]
    assert out.split(dense[0], 1)[1].lstrip().startswith(("--profile", "--resume")) or "--resume" in dense[0]
    assert sum(f"--pose runs/{profile}/pose_dense" in line for line in poses) == 12 + len(fast_rows)
    assert sum(f"--pose runs/{profile}/pose_dense --icp --verify" in line for line in poses) == 4
    assert sorted({re.search(r"_(?:gt|pred)_(\w+_paper)\.csv", line).group(1) for line in paper_rows}) == \
        (["fgr_icp_paper", "ransac_icp_paper", "super4pcs_paper"] if ycbv else [])
    assert all(line.startswith(".venv/bin/sixdpose register ") for line in paper_rows)
    sensor = [line for line in _lines(out, "evaluate") if f"--data {kinect} " in line]
    assert sorted(re.search(r"--result-name (\S+)", line).group(1) for line in sensor) == \
        ["test_kinect_gt_ransac_icp", "test_kinect_gt_super4pcs_icp"]
    kinect_gen = f".venv/bin/sixdpose generate --profile {splits[0][5:]} --set sensor=kinect --out {kinect} "
    assert any(line.startswith(kinect_gen) for line in _lines(out, "generate"))
    # paper: the pair trained "twice as long" would be the base pair again (the paper profile both times): left out
    n_real = {"cpu": 20, "paper": 18}.get(profile, 0)
    assert len(real) == n_real and len(_lines(out, "evaluate")) == len(evals) + len(real) + 2
    assert ({"data/ycbv", "data/ycbv_ideal"} <= gen) == ycbv
    # without the branch, notebook 09's smoke network and refiner on a tiny ycbv dataset
    assert (f"data/ycbv_{profile}" in gen) == (not ycbv)
    assert len([line for line in _lines(out, "train-pose") if "pose_ycbv" in line]) == \
        {"cpu": 7, "paper": 5}.get(profile, 1)
    assert len([line for line in _lines(out, "train-refiner") if "refiner_ycbv" in line]) == (2 if ycbv else 1)
    # notebook 05's ablations: each option alone (results/P/pose_ablation_P.json), then over 3 seeds with the
    # refiner-noise rows (pose_ablation_seeds_P.json), in the same run directory (shared seed-0 networks)
    ablation = re.findall(r"sixdpose pose-ablation (.*?)--result-name (\S+) --results-dir (\S+)",
                          out.replace("\\\n", ""))
    assert [a[1:] for a in ablation] == [(f"pose_ablation_{profile}", f"results/{profile}"),
                                         (f"pose_ablation_seeds_{profile}", f"results/{profile}")]
    assert all(("--val data/val" in a[0]) == (profile in ("cpu", "paper")) for a in ablation)
    assert "--seeds 3 --refiner-noise" in ablation[1][0] and "--seeds" not in ablation[0][0]
    assert len({re.search(r"--out (\S+)", a[0]).group(1) for a in ablation}) == 1
    long = [line for line in _lines(out, "train-pose") if "_e12" in line]  # the pair trained twice as long
    assert len(long) == (2 if profile == "cpu" else 0) and all(
        ("--epochs 12" in line) == (profile == "cpu") or "--resume" in line for line in long)
    assert all(f"--results-dir results/{profile}" in line for line in _lines(out, "evaluate"))
    assert sum("--masks gt --min-px 400" in line for line in poses) == 12 + len(paper_rows) // 2
    # every notebook reads what make wrote: no notebook trains, generates or writes a result
    assert "SEG_PROFILE" not in out
    assert len(re.findall(r"-m papermill .*notebooks/0\d_\w+\.ipynb notebooks/executed/" + profile, out)) == 9
    assert "latexmk" in out and f"-outdir=build/{profile}" in out
    # stages in the order of the pipeline: datasets, training, masks, then poses
    first = [out.index(s) for s in ("sixdpose generate", "sixdpose train-seg", "sixdpose segment", "sixdpose register")]
    assert first == sorted(first)


@pytest.mark.parametrize("profile", ["paper", "cpu", "demo", "smoke"])
def test_only_the_paper_profile_fetches_imagenet_weights_first(profile):
    out = _plan("reproduce", f"PROFILE={profile}").stdout
    fetch = ".venv/bin/sixdpose fetch-weights --backbone resnet50 --no-progress"
    commands = [line for line in out.splitlines() if line.startswith(".venv/bin/sixdpose ")]
    if profile == "paper":  # before anything else of the graph (train-seg starts from the weights)
        assert commands[0] == fetch and out.count(fetch) == 1
    else:
        assert "fetch-weights" not in out


@pytest.mark.parametrize("env", [{"TORCH_HOME": "{tmp}/th"}, {"XDG_CACHE_HOME": "{tmp}/xdg"}, {"HOME": "{tmp}/home"}])
def test_the_weights_target_is_the_file_torch_and_train_seg_load(env, tmp_path, monkeypatch):
    """mk/reproduce.mk's target for the ImageNet weights is the path torchvision (through torch.hub) and the
    segmentation stage look at, under each way of placing the torch hub cache."""
    from sixdpose.segmentation.model import cached_weights_path

    environ = {k: v for k, v in os.environ.items() if k not in ("TORCH_HOME", "XDG_CACHE_HOME")}
    environ.update({k: v.format(tmp=tmp_path) for k, v in env.items()})
    for k in ("TORCH_HOME", "XDG_CACHE_HOME", "HOME"):
        if k in environ:
            monkeypatch.setenv(k, environ[k])
        else:
            monkeypatch.delenv(k, raising=False)
    path = Path(cached_weights_path("resnet50"))
    assert path.is_relative_to(tmp_path)
    p = _plan(str(path), "PROFILE=paper", env=environ)
    assert p.returncode == 0, p.stderr
    assert p.stdout.splitlines()[-1] == ".venv/bin/sixdpose fetch-weights --backbone resnet50 --no-progress"


def test_smoke_runs_a_few_methods_and_lmo_adds_table_1():
    out = _plan("smoke", "WITH_LATEX=1").stdout
    # 16 = 4 methods x 2 splits x 2 mask sources, + 1 kinect row (ransac_icp: the smoke methods with ICP)
    assert len(_lines(out, "evaluate")) == 17 and "results/smoke/single_pred_super4pcs.json" not in out
    assert "--result-name test_kinect_gt_ransac_icp" in out and "test_kinect_gt_super4pcs_icp" not in out
    assert "--result-name pose_ablation_smoke" in out and "--epochs 3 --limit 4" in out
    out = _plan("reproduce", "PROFILE=cpu", "LMO=/data/lmo").stdout
    lmo = [line for line in _lines(out, "evaluate") if "--data /data/lmo" in line]
    assert len(lmo) == 12 and all("--split test" in line for line in lmo)
    assert any("--train-split train_pbr" in line for line in _lines(out, "train-seg"))


def test_profile_errors_are_one_line():
    p = _plan("reproduce", "PROFILE=laptop")
    assert p.returncode != 0 and "PROFILE=laptop: use one of smoke demo cpu paper" in p.stderr
    p = _plan("demo", "PROFILE=cpu")
    assert p.returncode != 0 and "make demo is PROFILE=demo" in p.stderr


_TRAIN = re.compile(r"\.venv/bin/sixdpose (train-seg|train-pose|train-refiner|pose-ablation) (.*)")


def trainings(out: str) -> dict[str, list[str]]:
    """Every training command of a ``make -n`` plan (continuation lines joined), keyed by what it trains:
    the command and its arguments without ``--out`` and ``--no-progress`` (same key: the same network);
    the values are the ``--out`` directories. A ``--resume`` command (the plan's choice where the directory
    holds a ``last.pt``, as the smoke graph running beside the tests leaves mid-training) continues that
    directory's own saved config, so its key is its directory."""
    found: dict[str, list[str]] = {}
    for line in out.replace("\\\n", " ").splitlines():
        m = _TRAIN.search(line)
        if m is None:
            continue
        args = " ".join(m.group(2).split())
        outdir = re.search(r"--out (\S+)", args).group(1)
        key = m.group(1) + " " + " ".join(re.sub(r"--out \S+|--no-progress", " ", args).split())
        if "--resume" in args.split():
            key += " " + outdir
        found.setdefault(key, []).append(outdir)
    return found


@pytest.mark.parametrize("profile", ["paper", "cpu", "demo", "smoke"])
def test_no_two_targets_train_the_same_network(profile):
    p = _plan("reproduce", f"PROFILE={profile}")
    assert p.returncode == 0, p.stderr
    found = trainings(p.stdout)
    assert len(found) >= 4  # seg, pose, refiner, ablation at least
    same = {k: v for k, v in found.items() if len(v) > 1}
    assert not same, f"targets training the same network (same data and config): {same}"


def test_the_duplicate_check_finds_a_duplicate():
    plan = (".venv/bin/sixdpose train-pose --data data/ycbv --out runs/p/a --no-progress --profile paper\n"
            ".venv/bin/sixdpose train-pose --data data/ycbv --out runs/p/b --no-progress \\\n  --profile paper\n"
            ".venv/bin/sixdpose train-pose --data data/ycbv --out runs/p/c --no-progress --profile paper --set x=1\n")
    found = trainings(plan)
    assert sorted(found.values(), key=len) == [["runs/p/c"], ["runs/p/a", "runs/p/b"]]
    # two directories being resumed (each continues its own saved config) are two networks
    resumed = (".venv/bin/sixdpose train-pose --data data/smoke --out runs/s/pose --no-progress --resume\n"
               ".venv/bin/sixdpose train-pose --data data/smoke --out runs/s/pose_dense --no-progress --resume\n")
    assert sorted(trainings(resumed).values()) == [["runs/s/pose"], ["runs/s/pose_dense"]]


# --------------------------------------------------------------------------------------------
# the write-up from the result files that are here (make tables / make paper): no stage command
# --------------------------------------------------------------------------------------------
_STAGE = re.compile(r"\bsixdpose (generate|train-seg|train-pose|train-refiner|segment|register|predict-pose|evaluate|"
                    r"pose-ablation)\b")


def _dry(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["make", "--no-print-directory", *args], cwd=REPO, capture_output=True, text=True,
                          timeout=120)


@pytest.mark.parametrize("goal", ["paper", "tables", "fig2"])
@pytest.mark.parametrize("flags", ["-n", "-nB"])
def test_the_write_up_runs_no_stage(goal, flags):
    """`make tables` / `make paper` (and `make fig2`) on the committed results/cpu list no stage command,
    even with every target out of date (-B): the results are inputs, not targets."""
    p = _dry(flags, goal, "PROFILE=cpu", "WITH_LATEX=1")
    assert p.returncode == 0, p.stderr
    assert _STAGE.findall(p.stdout) == [], f"make {flags} {goal} PROFILE=cpu runs stages:\n{p.stdout}"
    if goal != "fig2" and flags == "-nB":
        assert "07_evaluation.ipynb" in p.stdout  # notebook 07 builds the tables from results/cpu
        assert ("latexmk -pdf" in p.stdout) == (goal == "paper")
    # RECOMPUTE=yes is the graph again: the write-up waits for every stage
    p = _dry("-nB", goal, "PROFILE=cpu", "RECOMPUTE=yes")
    assert p.returncode == 0 and _STAGE.search(p.stdout), p.stderr


def test_the_write_up_without_results_is_one_line():
    """A profile without result files here (paper on a fresh clone): `make tables` says what computes them
    and writes nothing."""
    if list((REPO / "results" / "paper").glob("*.json")):
        pytest.skip("results/paper holds results in this checkout")
    p = _dry("tables", "PROFILE=paper", "-o", ".venv/.synced", "-o", ".venv/.apt")
    assert p.returncode == 2
    assert "results/paper holds no result file; make reproduce PROFILE=paper" in p.stderr
    assert not (REPO / "paper" / "generated" / "paper").exists()


def _copy_checkout(dest: Path) -> None:
    """The checkout's files (tracked and untracked, not ignored) in ``dest``, committed there, with this
    checkout's .venv linked in (ignored)."""
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=REPO, capture_output=True,
                           check=True).stdout.decode().split("\0")
    for f in filter(None, files):
        src = REPO / f
        if src.is_file():
            (dest / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / f)
    (dest / ".venv").symlink_to(REPO / ".venv")
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-c", "commit.gpgsign=false"]
    subprocess.run([*git, "init", "-q"], cwd=dest, check=True)
    (dest / ".git" / "info" / "exclude").write_text(".venv\n")
    subprocess.run([*git, "add", "-A"], cwd=dest, check=True)
    subprocess.run([*git, "commit", "-qm", "copy"], cwd=dest, check=True)


@pytest.mark.slow
@pytest.mark.skipif(not (REPO / ".venv" / "bin" / "python").exists(), reason="no .venv (make setup)")
def test_make_tables_on_the_committed_results_writes_no_result(tmp_path):
    """`make tables PROFILE=cpu` in a copy of the checkout: notebook 07 runs on the committed results/cpu
    (a few seconds), results/ is untouched, and the committed tables, macros and figures are what it
    writes (a change of the reporting code must come with them rebuilt: `make tables PROFILE=cpu`)."""
    _copy_checkout(tmp_path)
    for f in (tmp_path / "results" / "cpu").glob("*.json"):
        f.touch()  # results newer than the tables (a fresh clone's order of times is arbitrary): notebook 07 runs
    # with LaTeX, `make paper`: also the PDF, whose committed copy paper/sixdpose-cpu.pdf it must rewrite
    # unchanged (fixed PDF dates: the same inputs give the same bytes)
    goal = "paper" if shutil.which("latexmk") and shutil.which("pdflatex") else "tables"
    # -o: the linked .venv is this checkout's, set up already (its stamps are not remade)
    p = subprocess.run(["make", "--no-print-directory", goal, "PROFILE=cpu", "-o", ".venv/.synced", "-o",
                        ".venv/.apt"], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    assert _STAGE.findall(p.stdout) == []
    assert (tmp_path / "notebooks" / "executed" / "cpu" / "07_evaluation.ipynb").is_file()
    if goal == "paper":
        assert (tmp_path / "paper" / "build" / "cpu" / "paper.pdf").is_file()
    status = subprocess.run(["git", "status", "--porcelain", "--", "results"], cwd=tmp_path, capture_output=True,
                            text=True, check=True).stdout
    assert status == "", f"make tables wrote into results/:\n{status}"
    changed = subprocess.run(["git", "status", "--porcelain"], cwd=tmp_path, capture_output=True, text=True,
                             check=True).stdout
    assert changed == "", (f"make {goal} PROFILE=cpu changed committed files (rebuild them with it and commit):\n"
                           f"{changed}")
    again = subprocess.run(["make", "-q", goal, "PROFILE=cpu", "-o", ".venv/.synced", "-o", ".venv/.apt"],
                           cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert again.returncode == 0  # up to date: a second run does nothing


def test_a_run_stopped_before_its_first_checkpoint_is_resumed_not_refused(tmp_path):
    """A training run killed before its first epoch ended holds ``config.json`` but no ``last.pt``; the
    trainers refuse a fresh start into it ("already holds a run; use --resume"), so the graph must resume it."""
    target = f"{tmp_path}/seg_fast/model.pt"
    fresh = _plan(target, "PROFILE=cpu", f"RUNS={tmp_path}")
    assert fresh.returncode == 0, fresh.stderr
    assert "--resume" not in fresh.stdout and "--set backbone=mobilenet_v3_large" in fresh.stdout
    (tmp_path / "seg_fast").mkdir()
    (tmp_path / "seg_fast" / "config.json").write_text("{}")
    started = _plan(target, "PROFILE=cpu", f"RUNS={tmp_path}")
    assert started.returncode == 0, started.stderr
    line = next(x for x in started.stdout.split(".venv/bin/sixdpose ") if x.startswith("train-seg"))
    assert "--resume" in line and "--profile" not in line
