"""Fig. 2 (``sixdpose.reporting.fig2``): LM-O frames beside generated ones, captions computed from the GT."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from sixdpose.reporting import fig2
from test_reg_helpers import LMO, write_synthetic_dataset


def _png_size(path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", head[16:24])


def _rot_x(deg):
    a = math.radians(deg)
    return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])


def _sample(rotations, centres):
    from sixdpose.datasets.base import Instance, Sample

    insts = [Instance("a", 1, k, R, t) for k, (R, t) in enumerate(zip(rotations, centres, strict=False))]
    return Sample(0, 0, None, None, np.eye(3), insts)


def test_angles_of_known_cameras():
    # a camera looking 30 deg down at a table, no roll: the world's up is (0, -cos 30, -sin 30) in its frame
    up = np.array([0.0, -math.cos(math.radians(30)), -math.sin(math.radians(30))])
    view, roll = fig2.angles(up)
    assert view == pytest.approx(30) and roll == pytest.approx(0, abs=1e-9)
    rolled = np.array([[math.cos(0.2), -math.sin(0.2), 0], [math.sin(0.2), math.cos(0.2), 0], [0, 0, 1]]) @ up
    assert abs(fig2.angles(rolled)[1]) == pytest.approx(math.degrees(0.2))
    # objects on that table: the plane fit and the upright axes give the same up
    rng = np.random.default_rng(0)
    R_CW = _rot_x(120)  # camera frame from world frame: world up -> camera (0, -cos30, -sin30)
    assert np.allclose(R_CW @ [0, 0, 1], up)
    centres = np.array([R_CW @ [x, y, 0.0] + [0, 0, 1.0] for x, y in rng.uniform(-0.3, 0.3, (6, 2))])
    assert np.allclose(fig2.up_from_centres(centres), up)
    assert np.allclose(fig2.up_from_axes(np.stack([R_CW] * 5)), up)
    assert fig2.up_from_axes(np.stack([np.eye(3), _rot_x(90), _rot_x(180)])) is None  # objects lying anyhow
    assert fig2.up_from_centres(centres[:2]) is None
    # looking straight down, the roll is undefined and left out
    top = fig2.frame_view(_sample([np.eye(3)] * 3, centres), camera=(np.diag([1.0, -1.0, -1.0]), np.array([0, 2.0, 2])))
    assert top.view_deg == pytest.approx(90) and top.roll_deg is None and "roll n/a (top-down)" in fig2.caption(top)
    assert top.azimuth_deg == pytest.approx(90) and "az. +90°" in fig2.caption(top)  # the camera on the world's +y side
    # the camera's side about an upright reference object: the camera on the object's -x side
    R_CO = R_CW  # an upright object with the world's axes
    t_CO = R_CW @ np.array([1.0, 0.0, 0.0]) + [0, 0, 1.0]
    cam_W = -R_CW.T @ np.array([0, 0, 1.0])  # the camera centre in the world; the object sits at (1, 0, 0)
    v = fig2.frame_view(_sample([R_CO, R_CO], [t_CO, t_CO + 0.1]), ref_obj=1)
    want = np.degrees(np.arctan2(cam_W[1], cam_W[0] - 1.0))
    assert v.up_from == "object axes" and v.azimuth_deg == pytest.approx(want) and abs(want) > 90
    assert fig2.frame_view(_sample([R_CO, R_CO], [t_CO, t_CO + 0.1]), ref_obj=7).azimuth_deg is None
    assert fig2.azimuth_span([170, -170, 180]) == pytest.approx(20) and fig2.azimuth_span([0, 90, 180, 270]) == 270
    assert fig2.azimuth_span([5]) == 0


def test_fig2_png_from_a_synthetic_dataset_without_lmo(tmp_path):
    ds = write_synthetic_dataset(tmp_path / "syn", n_images=3)
    out = fig2.write_fig2(tmp_path / "no_lmo", ds, tmp_path / "f" / "fig2.png", n=2)
    assert _png_size(out) == (2 * 400, 760)
    from sixdpose.datasets.readers import open_dataset

    syn = open_dataset(ds)
    first = syn.load(syn.keys()[0], masks=False, rgb=False, depth=False)
    v = fig2.frame_view(first)
    assert v.repeated == {"035_power_drill": 2} and v.n_instances == 2 and v.n_objects == 1
    assert "2x 035_power_drill" in fig2.caption(v)
    assert fig2.main(["--lmo", str(tmp_path / "nothing"), "--ours", str(tmp_path / "missing"),
                      "--out", str(tmp_path / "x.png")]) == 1
    assert not (tmp_path / "x.png").exists()


@pytest.mark.skipif(not (LMO / "test").is_dir(), reason="LM-O sample not found")
def test_fig2_png_from_the_smoke_data_and_lmo(tiny_dataset, tmp_path):
    out = tmp_path / "figures" / "smoke" / "fig2_lmo_vs_ours.png"
    assert fig2.main(["--lmo", str(LMO), "--ours", str(tiny_dataset), "--out", str(out)]) == 0
    assert _png_size(out) == (3 * 400, 760)
    from sixdpose.datasets.readers import open_dataset

    lmo, ours = open_dataset(LMO, split="test"), open_dataset(tiny_dataset)
    s = lmo.load(lmo.keys()[0], masks=False, rgb=False, depth=False)
    v = fig2.frame_view(s)
    assert v.up_from == "object axes" and 0.3 < v.distance < 2.0 and not v.repeated
    assert fig2.summary(lmo, "LM-O").startswith(f"LM-O, {len(lmo)} frames: d ")
    o = ours.load(ours.keys()[0], masks=False, rgb=False, depth=False)
    assert fig2.frame_view(o, fig2._camera(ours, o)).up_from == "camera"
    assert "(up from: camera)" in fig2.summary(ours, "ours")
