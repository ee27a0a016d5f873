"""Your own objects (issue 11): any target set, BOP models as targets, a real dataset's camera, the
``ycbv`` profile, bad input. The two generator tests make tiny datasets (1 scene x 2 views each)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from sixdpose.assets import AssetError, load_mesh, sample_surface
from sixdpose.assets.bop import (
    DEFAULT_DENSITY_KG_M3,
    YCBV_YCB_NAMES,
    bake_face_colours,
    convert_bop_model,
    converted_model,
    list_bop_models,
    mesh_volume,
    model_mass,
)
from sixdpose.constants import MERGED_MASK_CODES, TARGET_OBJECTS, merged_mask_codes
from sixdpose.datasets.base import DatasetError
from sixdpose.datasets.ply import read_ply, write_ply

REPO = Path(__file__).resolve().parents[1]
YCBV_K = (1066.778, 1067.487, 312.9869, 241.3109)


def _shared() -> Path | None:
    for c in (os.environ.get("SIXDPOSE_SHARED"), REPO.parent / "shared", "/work/shared"):
        if c and Path(c).is_dir():
            return Path(c)
    return None


@pytest.fixture(scope="module")
def ycbv_models() -> Path:
    """The YCB-Video sample's BOP models directory (skips if absent)."""
    root = _shared()
    d = None if root is None else root / "data" / "ycbv_sample" / "models"
    if d is None or not (d / "models_info.json").is_file():
        pytest.skip("ycbv_sample models not found")
    return d


# ------------------------------------------------------------------------------------------
# small BOP-style PLYs (millimetres): a closed box, textured / vertex-coloured / plain / no faces
# ------------------------------------------------------------------------------------------
_BOX_F = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                   [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])


def _box_mm(size=(40.0, 60.0, 80.0), offset=(5.0, -3.0, 20.0)) -> np.ndarray:
    sx, sy, sz = np.asarray(size) / 2
    return np.array([[x, y, z] for x in (-sx, sx) for y in (-sy, sy) for z in (-sz, sz)], float) + offset


def _textured_ply(d: Path, name="obj_000007.ply") -> Path:
    """A box whose vertices with z > 0 (model frame) have uv v = 0.9 (texture top: red), the others v = 0.1
    (bottom: blue); OBJ/BOP convention, v = 0 at the bottom row."""
    from PIL import Image

    tex = np.zeros((8, 8, 3), np.uint8)
    tex[:4] = (255, 0, 0)
    tex[4:] = (0, 0, 255)
    Image.fromarray(tex).save(d / "tex7.png")
    V = _box_mm()
    uv = np.c_[np.full(len(V), 0.5), np.where(V[:, 2] > 20.0, 0.9, 0.1)]
    lines = ["ply", "format ascii 1.0", "comment TextureFile tex7.png", f"element vertex {len(V)}",
             "property float x", "property float y", "property float z", "property float texture_u",
             "property float texture_v", f"element face {len(_BOX_F)}", "property list uchar int vertex_indices",
             "end_header"]
    lines += [" ".join(f"{x:.6f}" for x in (*v, *t)) for v, t in zip(V, uv, strict=True)]
    lines += ["3 " + " ".join(map(str, f)) for f in _BOX_F]
    p = d / name
    p.write_text("\n".join(lines) + "\n")
    return p


def test_merged_mask_code_rule():
    assert merged_mask_codes(TARGET_OBJECTS) == MERGED_MASK_CODES  # the rule gives the paper's codes
    codes = list(merged_mask_codes([f"o{k}" for k in range(19)]).values())
    assert codes[0] == 13 and codes[-1] == 255 and min(np.diff(codes)) >= 4
    assert merged_mask_codes(["a"]) == {"a": 255}
    with pytest.raises(ValueError, match="at most 63"):
        merged_mask_codes(range(64))


def test_convert_textured_model(tmp_path):
    src = _textured_ply(tmp_path)
    obj = convert_bop_model(src, tmp_path / "conv")
    assert sorted(p.name for p in obj.parent.iterdir()) == ["texture_map.png", "textured.mtl", "textured.obj"]
    assert "map_Kd texture_map.png" in (obj.parent / "textured.mtl").read_text()
    m = load_mesh(obj)
    ply = read_ply(src)
    np.testing.assert_allclose(m.vertices, ply.vertices / 1000.0, atol=1e-9)  # mm -> m, same frame
    np.testing.assert_array_equal(m.faces, ply.faces)
    np.testing.assert_allclose(m.face_uvs, ply.uvs[ply.faces], atol=1e-9)  # uvs copied, no flip
    # colours through the converted OBJ (sixdpose's sampler, v = 0 at the bottom) are the PLY's texture colours
    pts, _, col = sample_surface(m, 400, seed=0)
    top = np.isclose(pts[:, 2], 0.060)  # the top face (z = 60 mm): red
    assert top.any() and np.allclose(col[top], [1, 0, 0])
    bottom = np.isclose(pts[:, 2], -0.020)
    assert bottom.any() and np.allclose(col[bottom], [0, 0, 1])


def test_convert_vertex_coloured_plain_and_faceless(tmp_path):
    V = _box_mm()
    col = np.where(V[:, :1] > 5.0, [[0.0, 1.0, 0.0]], [[1.0, 1.0, 0.0]])  # +x half green, -x half yellow
    write_ply(tmp_path / "obj_000001.ply", V, colors=col, faces=_BOX_F)
    m = load_mesh(convert_bop_model(tmp_path / "obj_000001.ply", tmp_path / "c1"))
    assert m.texture.shape[:2] == (4, 4)  # 12 faces -> one texel each, 4 x 4
    pts, _, c = sample_surface(m, 500, seed=1)
    plus_x = np.isclose(pts[:, 0], 0.025)  # the +x face (all its vertices green)
    assert plus_x.any() and np.allclose(c[plus_x], [0, 1, 0], atol=1 / 255)
    tex, uv = bake_face_colours(_BOX_F, col)
    assert uv.shape == (12, 2) and ((uv > 0) & (uv < 1)).all()
    # plain mesh: uniform grey; no faces: one line naming the file
    write_ply(tmp_path / "obj_000002.ply", V, faces=_BOX_F)
    m2 = load_mesh(convert_bop_model(tmp_path / "obj_000002.ply", tmp_path / "c2"))
    assert np.ptp(m2.texture) == 0 and abs(int(m2.texture[0, 0, 0]) - 153) <= 1
    write_ply(tmp_path / "obj_000003.ply", V)
    with pytest.raises(AssetError, match=r"obj_000003.ply: PLY has no faces"):
        convert_bop_model(tmp_path / "obj_000003.ply", tmp_path / "c3")
    assert not (tmp_path / "c3").exists()


def test_conversion_cache_and_mass(tmp_path):
    src = _textured_ply(tmp_path)
    obj, digest = converted_model(src, tmp_path / "cache")
    stamp = obj.stat().st_mtime_ns
    obj2, digest2 = converted_model(src, tmp_path / "cache")
    assert (obj2, digest2) == (obj, digest) and obj.stat().st_mtime_ns == stamp  # converted once
    from PIL import Image

    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(tmp_path / "tex7.png")  # the texture is content too
    obj3, digest3 = converted_model(src, tmp_path / "cache")
    assert digest3 != digest and obj3 != obj
    m = load_mesh(obj, with_texture=False)
    vol = 0.040 * 0.060 * 0.080
    assert np.isclose(mesh_volume(m), vol) and np.isclose(model_mass(m), DEFAULT_DENSITY_KG_M3 * vol)
    assert model_mass(m, ycb_mass=0.603) == 0.603


def test_bop_camera_loader(tmp_path, ycbv_models):
    from sixdpose.generation import camera_from_bop, profile

    ov = camera_from_bop(ycbv_models.parent / "train_real" / "000000" / "scene_camera.json")
    assert ov == {"camera.intrinsics": YCBV_K, "camera.width": 640, "camera.height": 480}  # size from rgb/
    (tmp_path / "camera.json").write_text(json.dumps({"fx": 500.0, "fy": 501.0, "cx": 159.5, "cy": 119.5,
                                                      "width": 320, "height": 240, "depth_scale": 0.1}))
    cfg = profile("smoke", **camera_from_bop(tmp_path / "camera.json"))
    assert (cfg.camera.width, cfg.camera.height, cfg.camera.intrinsics) == (320, 240, (500.0, 501.0, 159.5, 119.5))
    assert profile("ycbv").camera.intrinsics == YCBV_K
    (tmp_path / "bad.json").write_text(json.dumps({"0": {"depth_scale": 1.0}}))
    with pytest.raises(DatasetError, match=r"bad.json: no cam_K"):
        camera_from_bop(tmp_path / "bad.json")


def test_intrinsics_follow_the_camera_config():
    pytest.importorskip("pydrake")
    from sixdpose.generation import profile
    from sixdpose.generation.sim import camera_info, intrinsics

    cfg = profile("ycbv")
    K = intrinsics(cfg)
    np.testing.assert_allclose(K, [[YCBV_K[0], 0, YCBV_K[2]], [0, YCBV_K[1], YCBV_K[3]], [0, 0, 1]], atol=1e-9)
    info = camera_info(cfg)
    assert (info.width(), info.height()) == (640, 480) and np.isclose(info.center_x(), YCBV_K[2] + 0.5)
    assert intrinsics(profile("smoke"))[0, 2] == 319.0  # unchanged without explicit intrinsics


def test_resolve_ycbv_objects(tmp_path, ycb_dir, ycbv_models):
    from sixdpose.generation import profile, resolve_objects

    cfg = profile("ycbv")
    assert cfg.target_objects == tuple(f"obj_{k:06d}" for k in range(1, 22) if k not in (4, 19))  # the 19 textured
    assert cfg.symmetric_objects == tuple(f"obj_{k:06d}" for k in (1, 13, 14, 16, 18, 20, 21))
    assert (cfg.target_source, cfg.bop_ycb_map, cfg.sensor, cfg.bop_export) == ("bop", "ycbv", "kinect", "train_synt")
    assert merged_mask_codes(cfg.target_objects)["obj_000002"] == 26  # 19 targets: 13, 26, ..., 255
    # three of them (converting all 19 takes 10 s): given in any order and any spelling
    objs = resolve_objects(cfg.replace(target_objects=("13", "006_mustard_bottle", "obj_000001")), ycb_dir, ycbv_models,
                           cache_dir=tmp_path / "cache")
    assert [t.obj_id for t in objs.targets] == [1, 5, 13]
    assert objs.target_names == ["obj_000001", "obj_000005", "obj_000013"]
    assert [t.symmetric for t in objs.targets] == [True, False, True]
    assert objs.codes == {"obj_000001": 85, "obj_000005": 170, "obj_000013": 255}
    target_ycb = {YCBV_YCB_NAMES[k - 1] for k in (1, 5, 13)}
    assert not target_ycb & set(objs.noise_names) and len(objs.noise_names) == 46 - 3
    mustard = objs.targets[1]
    assert mustard.ycb_name == "006_mustard_bottle" and mustard.mass == 0.603  # objects.csv
    # no map: density x volume; YCB names are then unknown as targets
    cfg2 = cfg.replace(bop_ycb_map=None, symmetric_objects=None, target_objects=("5",))
    o2 = resolve_objects(cfg2, ycb_dir, ycbv_models, cache_dir=tmp_path / "cache")
    assert o2.targets[0].mass != 0.603 and "006_mustard_bottle" in o2.noise_names
    with pytest.raises(AssetError, match="unknown target object '006_mustard_bottle'"):
        resolve_objects(cfg2.replace(target_objects=("006_mustard_bottle",)), ycb_dir, ycbv_models,
                        cache_dir=tmp_path / "cache")
    with pytest.raises(AssetError, match="both target and noise: 006_mustard_bottle"):
        resolve_objects(cfg.replace(target_objects=("5",), noise_objects=("006_mustard_bottle",)), ycb_dir, ycbv_models,
                        cache_dir=tmp_path / "cache")
    assert list_bop_models(ycbv_models)[13].symmetric is False  # the sample has no symmetry annotations


# ------------------------------------------------------------------------------------------
# bad input on the command line: one line, exit status 2, nothing written
# ------------------------------------------------------------------------------------------
def _bad_inputs(tmp: Path):
    (tmp / "faceless").mkdir()
    write_ply(tmp / "faceless" / "obj_000001.ply", _box_mm())
    (tmp / "nocam.json").write_text(json.dumps({"1": {"depth_scale": 0.1}}))
    return [
        (["--assets-bop", str(tmp / "nope" / "models")], "nope/models: BOP models directory not found"),
        (["--assets-bop", str(tmp / "faceless")], "obj_000001.ply: PLY has no faces"),
        (["--targets", "006_mustard_bottle,no_such_thing"], "unknown target object(s) no_such_thing"),
        (["--noise", "no_such_noise"], "unknown noise object(s) no_such_noise"),
        (["--camera", str(tmp / "nocam.json")], "nocam.json: no cam_K"),
        (["--camera", str(tmp / "missing.json")], "missing.json: file not found"),
        (["--set", "camera.intrinsics=[500, 500, 700, 200]"], "principal point"),
    ]


def test_bad_input_is_one_line(tmp_path, ycb_dir, capsys, monkeypatch):
    from sixdpose.cli import main

    monkeypatch.setenv("SIXDPOSE_CACHE", str(tmp_path / "cache"))
    for extra, message in _bad_inputs(tmp_path):
        out = tmp_path / "out"
        rc = main(["generate", "--profile", "smoke", "--out", str(out), "--assets", str(ycb_dir), "--no-progress",
                   *extra])
        err = capsys.readouterr().err
        assert rc == 2 and message in err and len(err.strip().splitlines()) == 1, (extra, err)
        assert not out.exists()


# ------------------------------------------------------------------------------------------
# tiny datasets (Drake)
# ------------------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.drake
def test_custom_target_set(tmp_path, ycb_dir):
    """Three YCB targets of our choice: obj_ids are their list positions, codes follow the rule, the GT is
    exact, and the noise pool never holds a target."""
    from PIL import Image

    from sixdpose.generation import generate, profile
    from sixdpose.generation.checks import gt_surface_errors

    targets = ("035_power_drill", "006_mustard_bottle", "025_mug")
    cfg = profile("smoke", scenes=1, views=2, targets=(4, 6), target_objects=targets)
    out = tmp_path / "custom"
    res = generate(out, cfg, assets=ycb_dir, progress=False)
    assert not res["scenes_failed"]
    info = yaml.safe_load((out / "models" / "models_info.yml").read_text())
    codes = merged_mask_codes(targets)
    assert {n: v["obj_id"] for n, v in info.items()} == {n: k + 1 for k, n in enumerate(targets)}
    assert {n: v["mask_code"] for n, v in info.items()} == codes == {targets[0]: 85, targets[1]: 170, targets[2]: 255}
    assert sorted(p.stem for p in (out / "models").glob("*.ply")) == sorted(targets)
    assert yaml.safe_load((out / "config.yml").read_text())["target_objects"] == list(targets)
    gt = yaml.safe_load((out / "gt.yml").read_text())
    n_inst = 0
    for im_id, e in gt.items():
        merged = np.asarray(Image.open(out / "merged_masks" / f"{im_id}.png"))
        expect = np.zeros_like(merged)
        for o in e["objects"]:
            m = np.asarray(Image.open(out / "masks" / o["obj_name"] / f"{im_id}_{o['inst']}.png")) > 0
            expect[m] = codes[o["obj_name"]] - o["inst"]
            assert o["obj_id"] == targets.index(o["obj_name"]) + 1
            n_inst += 1
        assert (merged == expect).all()
    assert n_inst >= 2
    man = json.loads((out / "manifest.json").read_text())
    for sc in man["scenes"].values():
        for o in sc["objects"]:
            assert (o["role"] == "target") == (o["name"] in targets)
    errs = gt_surface_errors(out, ycb_dir)
    assert errs and max(e["mean"] for e in errs) < 1e-4


@pytest.mark.slow
@pytest.mark.drake
def test_bop_model_targets(tmp_path, ycb_dir, ycbv_models):
    """Three ycbv models as targets with the YCB-Video camera and the ideal sensor: every visible instance's
    back-projected depth lies on the *original BOP PLY* (mm -> m) at the GT pose (mean < 1 mm; in fact
    about 1e-4 mm, so K, frames and units all agree), obj_ids are the BOP ids, and the BOP copy carries them."""
    import open3d as o3d

    from sixdpose.datasets import open_dataset
    from sixdpose.datasets.geometry import backproject
    from sixdpose.generation import generate, profile

    cfg = profile("ycbv", scenes=1, views=2, targets=(4, 6), noise=(2, 3), sensor="ideal",
                  target_objects=("2", "obj_000005", "035_power_drill"))
    out = tmp_path / "bop"
    res = generate(out, cfg, assets=ycb_dir, assets_bop=ycbv_models, cache_dir=tmp_path / "cache", progress=False)
    assert not res["scenes_failed"] and res["bop_export"] == str(out / "bop")
    info = yaml.safe_load((out / "models" / "models_info.yml").read_text())
    assert {n: v["obj_id"] for n, v in info.items()} == {"obj_000002": 2, "obj_000005": 5, "obj_000015": 15}
    assert all(v["source"] == f"{n}.ply" and len(v["source_sha256"]) == 64 for n, v in info.items())

    ds = open_dataset(out)
    meshes = {}
    n_checked = 0
    for key in ds.keys():  # noqa: SIM118 (a dataset reader, not a dict: iterating it yields samples)
        s = ds.load(key)
        np.testing.assert_allclose(s.K, [[YCBV_K[0], 0, YCBV_K[2]], [0, YCBV_K[1], YCBV_K[3]], [0, 0, 1]])
        assert s.rgb.shape == (480, 640, 3)
        for inst in s.instances:
            assert inst.obj_name == f"obj_{inst.obj_id:06d}"
            if inst.obj_id not in meshes:
                ply = read_ply(ycbv_models / f"obj_{inst.obj_id:06d}.ply")
                rs = o3d.t.geometry.RaycastingScene()
                rs.add_triangles(o3d.core.Tensor((ply.vertices / 1000.0).astype(np.float32)),
                                 o3d.core.Tensor(ply.faces.astype(np.uint32)))
                meshes[inst.obj_id] = rs
            p_O = (backproject(s.depth, s.K, inst.mask)[0] - inst.t) @ inst.R  # camera -> BOP model frame, metres
            d = meshes[inst.obj_id].compute_distance(o3d.core.Tensor(p_O.astype(np.float32))).numpy()
            assert d.mean() < 1e-3, (key, inst.obj_id, d.mean())
            assert d.mean() < 5e-5  # half a pixel of K convention would be about 0.5 mm
            n_checked += 1
    assert n_checked >= 2
    man = json.loads((out / "manifest.json").read_text())
    noise = {o["name"] for sc in man["scenes"].values() for o in sc["objects"] if o["role"] == "noise"}
    assert noise and not noise & {"003_cracker_box", "006_mustard_bottle", "035_power_drill"}

    bop = open_dataset(out / "bop", split="train_synt")
    assert sorted(bop.object_ids) == [2, 5, 15]
    assert sorted(json.loads((out / "bop" / "models" / "models_info.json").read_text())) == ["15", "2", "5"]
    a, b = ds.load(ds.keys()[0]), bop.load(bop.keys()[0])
    assert [i.obj_id for i in a.instances] == [i.obj_id for i in b.instances]
    np.testing.assert_allclose(a.K, b.K)
    # resuming with other target models is refused
    from sixdpose.generation import GenerationError

    with pytest.raises(GenerationError, match="other target models"):
        info_path = out / "models" / "models_info.yml"
        info_path.write_text(info_path.read_text().replace("obj_id: 15", "obj_id: 16"))
        generate(out, cfg, assets=ycb_dir, assets_bop=ycbv_models, cache_dir=tmp_path / "cache", progress=False)
