"""YCB asset layer: catalogue, meshes, derived physics, and fetch-ycb against a local HTTP server."""

from __future__ import annotations

import http.server
import io
import subprocess
import sys
import tarfile
import threading
from pathlib import Path

import numpy as np
import pytest

from sixdpose.assets import (
    AssetError,
    MeshData,
    load_catalog,
    physical_properties,
    point_cloud_diameter,
    resolve_assets_dir,
    sample_surface,
)


def _cube(size=(0.1, 0.2, 0.3)) -> MeshData:
    sx, sy, sz = np.asarray(size) / 2
    V = np.array([[x, y, z] for x in (-sx, sx) for y in (-sy, sy) for z in (-sz, sz)], float) + [0.01, 0.02, 0.03]
    F = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return MeshData(V, F, None, None)


def test_box_physics_exact():
    m = _cube()
    pr = physical_properties(m, 2.0)
    assert pr.from_volume
    assert np.allclose(pr.com, [0.01, 0.02, 0.03]) and np.allclose(pr.box_center, pr.com)
    a, b, c = 0.1, 0.2, 0.3
    assert np.allclose(np.diag(pr.inertia), 2.0 / 12 * np.array([b * b + c * c, a * a + c * c, a * a + b * b]))
    assert np.allclose(pr.inertia - np.diag(np.diag(pr.inertia)), 0, atol=1e-12)


def test_open_mesh_falls_back_to_box():
    m = _cube()
    m = MeshData(m.vertices, m.faces[:, ::-1], None, None)  # inward-facing triangles: negative volume
    pr = physical_properties(m, 1.0)
    assert not pr.from_volume and np.allclose(pr.com, pr.box_center)


def test_sample_surface_and_diameter():
    m = _cube()
    pts, nrm, col = sample_surface(m, 5000, seed=1)
    lo, hi = m.vertices.min(0), m.vertices.max(0)
    assert (pts >= lo - 1e-12).all() and (pts <= hi + 1e-12).all()
    on_face = np.isclose(pts, lo).any(1) | np.isclose(pts, hi).any(1)
    assert on_face.all() and np.allclose(np.linalg.norm(nrm, axis=1), 1)
    assert np.allclose(col, 0.5)
    # diameter of a box is its space diagonal; brute force over the sampled points agrees
    assert np.isclose(point_cloud_diameter(m.vertices), np.linalg.norm([0.1, 0.2, 0.3]))
    sub = pts[:800]
    brute = np.linalg.norm(sub[:, None] - sub[None], axis=-1).max()
    assert np.isclose(point_cloud_diameter(sub), brute)


def test_catalogue(ycb_dir):
    cat = load_catalog(ycb_dir)
    from sixdpose.constants import TARGET_OBJECTS

    assert len(cat) == 46 and set(TARGET_OBJECTS) <= set(cat)
    # the paper's starred objects (section III-B), from the one source of the flag
    assert {n for n, o in cat.items() if o.symmetric} == {"056_tennis_ball", "053_mini_soccer_ball", "013_apple",
                                                          "029_plate"}


def test_resolve_errors(tmp_path, monkeypatch):
    with pytest.raises(AssetError, match="not found"):
        resolve_assets_dir(tmp_path / "nope")
    monkeypatch.setenv("SIXDPOSE_YCB", str(tmp_path))
    assert resolve_assets_dir() == tmp_path
    with pytest.raises(AssetError, match="objects.csv"):
        load_catalog(tmp_path)
    (tmp_path / "objects.csv").write_text("name,mass_kg,role,symmetric\nfoo,abc,target,0\n")
    with pytest.raises(AssetError, match="objects.csv:2"):
        load_catalog(tmp_path)


# ---------------------------------------------------------------------------- fetch-ycb
def _archive(ycb_dir: Path, name: str) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tf:
        for f in ("textured.obj", "textured.mtl", "texture_map.png"):
            tf.add(ycb_dir / name / "google_16k" / f, arcname=f"{name}/google_16k/{f}")
    return buf.getvalue()


@pytest.fixture
def server(ycb_dir):
    good = _archive(ycb_dir, "055_baseball")
    files = {
        "/055_baseball_google_16k.tgz": (good, len(good)),
        "/056_tennis_ball_google_16k.tgz": (b"\x1f\x8b\x08 this is not a gzip stream" * 50, None),
        "/013_apple_google_16k.tgz": (good[: len(good) // 3], len(good)),  # connection cut short
    }

    class H(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            if self.path not in files:
                self.send_error(404)
                return
            body, length = files[self.path]
            self.send_response(200)
            self.send_header("Content-Length", str(length or len(body)))
            self.end_headers()
            self.wfile.write(body)
            self.wfile.flush()
            self.close_connection = True

        def log_message(self, *a):
            pass

    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), H)
    t = threading.Thread(target=srv.serve_forever, daemon=True)
    t.start()
    yield f"http://127.0.0.1:{srv.server_address[1]}"
    srv.shutdown()


def _fetch(to, base, *objects):
    return subprocess.run([sys.executable, "-m", "sixdpose", "fetch-ycb", "--to", str(to), "--base-url", base,
                           "--timeout", "10", "--objects", *objects], capture_output=True, text=True)


def test_fetch_good(tmp_path, server, ycb_dir):
    r = _fetch(tmp_path / "y", server, "055_baseball")
    assert r.returncode == 0, r.stderr
    cat = load_catalog(tmp_path / "y")
    assert list(cat) == ["055_baseball"] and cat["055_baseball"].mass == pytest.approx(0.138)
    got = (tmp_path / "y" / "055_baseball" / "google_16k" / "textured.obj").read_bytes()
    assert got == (ycb_dir / "055_baseball" / "google_16k" / "textured.obj").read_bytes()


@pytest.mark.parametrize("obj, msg", [("056_tennis_ball", "corrupt archive"), ("013_apple", "incomplete download"),
                                      ("058_golf_ball", "HTTP 404"), ("999_nothing", "unknown YCB object")])
def test_fetch_failures_leave_nothing(tmp_path, server, obj, msg):
    to = tmp_path / "y"
    r = _fetch(to, server, obj)
    errors = [line for line in r.stderr.splitlines() if "error:" in line]
    assert r.returncode == 2 and len(errors) == 1 and msg in errors[0]
    # the ownership marker stays
    leftovers = [p for p in to.rglob("*") if p.name not in ("objects.csv", ".sixdpose.json")] if to.exists() else []
    assert leftovers == []
