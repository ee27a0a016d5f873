"""benchmarks/pose.py: the end-to-end timing with an untrained Mask R-CNN of a profile (``--seg-profile``)."""

import importlib.util
import json
from pathlib import Path

import pytest

from test_reg_helpers import write_synthetic_dataset

REPO = Path(__file__).resolve().parents[1]


def _bench():
    spec = importlib.util.spec_from_file_location("bench_pose", REPO / "benchmarks" / "pose.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_seg_profile_times_segmentation_and_pose_on_every_frame(tmp_path, capsys):
    """An untrained smoke Mask R-CNN made to return each frame's object count, then the dense head on the GT
    masks: the end-to-end figures are written, with as many detections per frame as the frames have objects;
    --seg and --seg-profile together, or --seg-profile without --data, are refused with exit status 2."""
    bench = _bench()
    data = write_synthetic_dataset(tmp_path / "d", n_images=3)
    pose, _ = bench.fake_runs("smoke", tmp_path, classes=16, head="dense", appearance="local")
    out = tmp_path / "out.json"
    args = ["--profile", "smoke", "--pose", str(pose), "--data", str(data), "--seg-profile", "smoke",
            "--frames", "2", "--steps", "1", "--no-result", "--json", str(out)]
    assert bench.main(args) == 0
    fig = json.loads(out.read_text())
    assert fig["e2e_frames"] == 2 and fig["e2e_fps"] > 0 and fig["infer_fps"] > 0
    assert fig["e2e_detections_per_frame"] == fig["infer_instances_per_frame"] == 1.0  # frames 1 and 2: one object
    assert "untrained" in fig["e2e_segmentation"]
    assert bench.main(args + ["--seg", str(tmp_path)]) == 2
    assert bench.main(["--pose", str(pose), "--seg-profile", "smoke", "--no-result"]) == 2
    assert "--seg/--seg-profile need --data" in capsys.readouterr().err


def test_repeats_report_the_median_pass_and_the_spread(tmp_path, capsys):
    """--repeats N times N passes over the frames and reports the median pass with the slowest and fastest, and
    that pass' segmentation and pose-stage times; --repeats 0 is refused with exit status 2; median_pass picks
    the pass of median mean."""
    bench = _bench()
    data = write_synthetic_dataset(tmp_path / "d", n_images=3)
    pose, _ = bench.fake_runs("smoke", tmp_path, classes=16, head="dense", appearance="local")
    out = tmp_path / "out.json"
    args = ["--profile", "smoke", "--pose", str(pose), "--data", str(data), "--seg-profile", "smoke",
            "--frames", "2", "--steps", "1", "--no-result", "--json", str(out), "--repeats", "3"]
    assert bench.main(args) == 0
    fig = json.loads(out.read_text())
    assert fig["e2e_passes"] == fig["infer_passes"] == 3
    assert fig["e2e_fps_min"] <= fig["e2e_fps"] <= fig["e2e_fps_max"]
    assert fig["infer_fps_min"] <= fig["infer_fps"] <= fig["infer_fps_max"]
    # the reported pass' two parts: Mask R-CNN and the pose stage, within the frame's time (the rest: the loop)
    seg_ms, pose_ms = fig["e2e_seg_ms_per_frame"], fig["e2e_pose_ms_per_frame"]
    assert seg_ms > 0 and pose_ms > 0 and 0.8 * fig["e2e_ms_per_frame"] <= seg_ms + pose_ms <= fig["e2e_ms_per_frame"]
    with pytest.raises(SystemExit) as e:
        bench.main(args[:-1] + ["0"])
    assert e.value.code == 2 and "--repeats" in capsys.readouterr().err

    import torch

    clock = iter([0.0, 3.0, 3.0, 4.0, 4.0, 6.0])  # passes of 3, 1 and 2 s: the median is the 2 s one
    bench.time.perf_counter, real = (lambda: next(clock)), bench.time.perf_counter
    try:
        times, means = bench.median_pass(lambda x: None, [0], torch.device("cpu"), 3)
    finally:
        bench.time.perf_counter = real
    assert times == [2.0] and means == [3.0, 1.0, 2.0]


def test_slides_saved_where_open3d_is_are_used_instead_of_building_them(tmp_path, monkeypatch, capsys):
    """--save-slides writes each object's colour-named slides (built from the model with Open3D) and stops;
    --slides hands them to the estimator, which then never builds them (a lent GPU machine has no Open3D),
    here with an untrained MobileNetV3 Mask R-CNN (--seg-backbone) in float32 (--seg-set amp=false) and the pose
    networks in float32 (--fp32); a --slides file that is not one, --seg-backbone without --seg-profile, or a
    --seg-set field that cannot change at inference, is refused with exit status 2."""
    bench = _bench()
    data = write_synthetic_dataset(tmp_path / "d", n_images=3)
    # shape flips named by colour (appearance local, flip_choice auto): the estimator scores the slides
    pose, _ = bench.fake_runs("smoke", tmp_path, classes=16, head="dense", appearance="local",
                              overrides={"flips": 4})
    npz = tmp_path / "slides.npz"
    base = ["--profile", "smoke", "--pose", str(pose), "--data", str(data), "--frames", "2", "--no-result"]
    assert bench.main(base + ["--save-slides", str(npz)]) == 0
    saved = bench.load_slides(str(npz))
    assert list(saved) == [15] and saved[15].shape[1:] == (4, 4)  # the drill, the dataset's one object

    import sixdpose.registration as reg

    def no_build(*a, **k):
        raise AssertionError("slides built although they were given")

    monkeypatch.setattr(reg, "model_slides", no_build)
    out = tmp_path / "out.json"
    args = base + ["--slides", str(npz), "--seg-profile", "smoke", "--seg-backbone", "mobilenet_v3_large",
                   "--fp32", "--seg-set", "amp=false", "--steps", "1", "--json", str(out)]
    assert bench.main(args) == 0
    assert json.loads(out.read_text())["e2e_frames"] == 2
    (tmp_path / "bad.npz").write_text("not an npz")
    assert bench.main(base + ["--slides", str(tmp_path / "bad.npz")]) == 2
    assert "bad.npz: not slides written by --save-slides" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:  # argparse: an unknown backbone, one line naming the option
        bench.main(base + ["--seg-profile", "smoke", "--seg-backbone", "vgg"])
    assert e.value.code == 2 and "--seg-backbone" in capsys.readouterr().err
    assert bench.main(base + ["--seg-backbone", "mobilenet_v3_large"]) == 2
    assert "--seg-backbone needs --seg-profile" in capsys.readouterr().err
    assert bench.main(base + ["--seg-profile", "smoke", "--seg-set", "backbone=resnet50"]) == 2
    assert "cannot change at inference" in capsys.readouterr().err
