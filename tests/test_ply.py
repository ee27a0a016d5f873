"""PLY reader/writer (sixdpose.datasets.ply): formats, textures, errors, real BOP models."""

from __future__ import annotations

import json
import os
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest

from sixdpose.datasets.base import DatasetError
from sixdpose.datasets.ply import PlyData, read_ply, sample_texture, write_ply

REPO = Path(__file__).resolve().parents[1]


def _shared() -> Path | None:
    """``$SIXDPOSE_SHARED``, else ``<repo>/../shared``, else ``/work/shared`` (None if none exists)."""
    cands = [os.environ.get("SIXDPOSE_SHARED"), REPO.parent / "shared", "/work/shared"]
    for c in cands:
        if c and Path(c).is_dir():
            return Path(c)
    return None


def _data_dir(*parts) -> Path:
    root = _shared()
    d = None if root is None else root.joinpath("data", *parts)
    if d is None or not d.is_dir():
        pytest.skip(f"shared test data not found ({'/'.join(parts)})")
    return d


def _write_bytes(path: Path, header: list[str], body: bytes = b"") -> Path:
    path.write_bytes(("\n".join(header) + "\n").encode("ascii") + body)
    return path


@pytest.fixture
def mesh():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(40, 3)) * 50.0
    nrm = rng.normal(size=(40, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    col = rng.integers(0, 256, size=(40, 3)) / 255.0
    faces = rng.integers(0, 40, size=(25, 3))
    return pts, nrm, col, faces


# ------------------------------------------------------------------------------------------
# round trips
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("with_normals", [False, True])
@pytest.mark.parametrize("with_colors", [False, True])
@pytest.mark.parametrize("with_faces", [False, True])
def test_write_read_round_trip(tmp_path, mesh, with_normals, with_colors, with_faces):
    pts, nrm, col, faces = mesh
    p = write_ply(
        tmp_path / "m.ply",
        pts,
        normals=nrm if with_normals else None,
        colors=col if with_colors else None,
        faces=faces if with_faces else None,
    )
    d = read_ply(p)
    assert isinstance(d, PlyData)
    assert d.vertices.dtype == np.float64 and d.vertices.shape == (40, 3)
    np.testing.assert_allclose(d.vertices, pts, rtol=1e-6, atol=1e-5)
    if with_normals:
        np.testing.assert_allclose(d.normals, nrm, atol=1e-6)
    else:
        assert d.normals is None
    if with_colors:
        np.testing.assert_allclose(d.colors, col, atol=1e-12)  # exact multiples of 1/255
    else:
        assert d.colors is None
    if with_faces:
        assert d.faces.dtype == np.int64
        np.testing.assert_array_equal(d.faces, faces)
    else:
        assert d.faces is None
    assert d.texture_file is None
    # atomic write: no temporary file left behind
    assert [q.name for q in tmp_path.iterdir()] == ["m.ply"]


def test_write_replaces_existing_file_and_rejects_bad_input(tmp_path, mesh):
    pts, nrm, col, faces = mesh
    p = tmp_path / "m.ply"
    write_ply(p, pts)
    write_ply(p, pts[:5])
    assert read_ply(p).vertices.shape == (5, 3)
    with pytest.raises(ValueError):
        write_ply(p, pts[:, :2])
    with pytest.raises(ValueError):
        write_ply(p, pts, faces=np.array([[0, 1, 40]]))
    with pytest.raises(ValueError):
        write_ply(p, pts, normals=nrm[:3])
    assert read_ply(p).vertices.shape == (5, 3)  # failed writes left the old file intact
    assert sorted(q.name for q in tmp_path.iterdir()) == ["m.ply"]


def test_ascii_by_hand_with_all_property_spellings(tmp_path):
    header = [
        "ply",
        "format ascii 1.0",
        "comment hand made",
        "element vertex 4",
        "property float32 x",
        "property double y",
        "property short z",
        "property float nx",
        "property float ny",
        "property float nz",
        "property uint8 red",
        "property uchar green",
        "property uchar blue",
        "property uchar alpha",
        "element face 2",
        "property list uint8 int32 vertex_index",
        "element edge 1",
        "property int vertex1",
        "property int vertex2",
        "end_header",
    ]
    body = (
        "0 0 0 0 0 1 255 0 0 255\n"
        "1.5 0 0 0 0 1 0 255 0 255\n"
        "0 2.25 -3 0 0 1 0 0 255 255\n"
        "1 1 7 0 0 1 51 102 153 255\n"
        "3 0 1 2\n"
        "3 1 3 2\n"
        "0 3\n"
    )
    p = _write_bytes(tmp_path / "a.ply", header, body.encode())
    d = read_ply(p)
    np.testing.assert_array_equal(d.vertices, [[0, 0, 0], [1.5, 0, 0], [0, 2.25, -3], [1, 1, 7]])
    np.testing.assert_array_equal(d.normals, np.tile([0, 0, 1], (4, 1)))
    np.testing.assert_allclose(d.colors, [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.2, 0.4, 0.6]], atol=1e-12)
    np.testing.assert_array_equal(d.faces, [[0, 1, 2], [1, 3, 2]])


def test_quads_and_polygons_are_fan_triangulated(tmp_path):
    # ascii, mixed quad / triangle / pentagon rows (slow path) ...
    header = ["ply", "format ascii 1.0", "element vertex 6"] + [f"property float {c}" for c in "xyz"]
    header += ["element face 3", "property list uchar int vertex_indices", "end_header"]
    verts = "\n".join(f"{i} {i * i} 0" for i in range(6))
    body = verts + "\n4 0 1 2 3\n3 3 4 5\n5 0 1 2 3 4\n"
    d = read_ply(_write_bytes(tmp_path / "q.ply", header, body.encode()))
    np.testing.assert_array_equal(
        d.faces, [[0, 1, 2], [0, 2, 3], [3, 4, 5], [0, 1, 2], [0, 2, 3], [0, 3, 4]]
    )
    # ... and binary, all quads (fast path)
    header[1] = "format binary_little_endian 1.0"
    header[-3] = "element face 2"
    vb = np.array([[i, i * i, 0] for i in range(6)], "<f4").tobytes()
    fb = b"".join(struct.pack("<B4i", 4, *q) for q in ([0, 1, 2, 3], [2, 3, 4, 5]))
    d = read_ply(_write_bytes(tmp_path / "qb.ply", header, vb + fb))
    np.testing.assert_array_equal(d.faces, [[0, 1, 2], [0, 2, 3], [2, 3, 4], [2, 4, 5]])


@pytest.mark.parametrize("endian", ["<", ">"])
def test_binary_both_endiannesses_and_integer_types(tmp_path, endian):
    name = {"<": "binary_little_endian", ">": "binary_big_endian"}[endian]
    header = [
        "ply",
        f"format {name} 1.0",
        "element material 2",  # unknown element with variable-length lists: read past, dropped
        "property uchar id",
        "property list uchar float weights",
        "element vertex 3",
        "property double x",
        "property int y",
        "property float z",
        "property ushort red",
        "property ushort green",
        "property ushort blue",
        "element face 1",
        "property list uchar uint vertex_indices",
        "end_header",
    ]
    vdt = np.dtype([("x", endian + "f8"), ("y", endian + "i4"), ("z", endian + "f4"),
                    ("r", endian + "u2"), ("g", endian + "u2"), ("b", endian + "u2")])
    v = np.array([(0.5, -7, 1.25, 0, 65535, 13107), (1e3, 2, -2.5, 65535, 0, 0), (-3.0, 100000, 0.0, 1, 2, 3)], vdt)
    f = struct.pack(endian + "B3I", 3, 2, 1, 0)
    mat = struct.pack(endian + "BB2f", 1, 2, 0.5, 0.25) + struct.pack(endian + "BBf", 2, 1, 1.0)
    d = read_ply(_write_bytes(tmp_path / "b.ply", header, mat + v.tobytes() + f))
    np.testing.assert_array_equal(d.vertices, [[0.5, -7, 1.25], [1e3, 2, -2.5], [-3.0, 100000, 0.0]])
    np.testing.assert_allclose(d.colors[0], [0, 1, 0.2], atol=1e-12)
    np.testing.assert_array_equal(d.faces, [[2, 1, 0]])


def test_float_colors_are_kept(tmp_path):
    header = ["ply", "format ascii 1.0", "element vertex 2"] + [f"property float {c}" for c in "xyz"]
    header += ["property float red", "property float green", "property float blue", "end_header"]
    d = read_ply(_write_bytes(tmp_path / "f.ply", header, b"0 0 0 0.25 0.5 0.75\n1 1 1 1 0 0.125\n"))
    np.testing.assert_allclose(d.colors, [[0.25, 0.5, 0.75], [1, 0, 0.125]])
    assert d.faces is None and d.normals is None


# ------------------------------------------------------------------------------------------
# textures
# ------------------------------------------------------------------------------------------
# 2x2 texture, row 0 is the TOP of the image: v = 1 samples row 0, v = 0 samples row 1
_TEX = np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [255, 255, 255]]], np.uint8)


def _textured_ply(tmp_path: Path, uv, tex_name="tex.png", write_texture=True, fmt="binary_little_endian") -> Path:
    from PIL import Image

    if write_texture:
        Image.fromarray(_TEX).save(tmp_path / tex_name)
    n = len(uv)
    header = ["ply", f"format {fmt} 1.0", f"comment TextureFile {tex_name}", f"element vertex {n}"]
    header += [f"property float {c}" for c in ("x", "y", "z", "nx", "ny", "nz", "texture_u", "texture_v")]
    header += ["element face 1", "property list uchar int vertex_indices", "end_header"]
    rows = np.array([[i, 0, 0, 0, 0, 1, u, v] for i, (u, v) in enumerate(uv)], np.float32)
    if fmt == "ascii":
        body = "\n".join(" ".join(repr(float(x)) for x in r) for r in rows) + "\n3 0 1 2\n"
        return _write_bytes(tmp_path / "t.ply", header, body.encode())
    return _write_bytes(tmp_path / "t.ply", header, rows.astype("<f4").tobytes() + struct.pack("<B3i", 3, 0, 1, 2))


@pytest.mark.parametrize("fmt", ["binary_little_endian", "ascii"])
def test_texture_colours_exact_with_v_flip(tmp_path, fmt):
    uv = [(0, 0), (1, 0), (0, 1), (1, 1), (0.5, 0.5), (0.5, 1.0), (0.25, 0.0), (1.5, 0.0), (-0.25, 1.0)]
    d = read_ply(_textured_ply(tmp_path, uv, fmt=fmt))
    T = _TEX / 255.0
    expected = [
        T[1, 0],  # (0, 0): bottom-left
        T[1, 1],  # (1, 0): bottom-right
        T[0, 0],  # (0, 1): top-left
        T[0, 1],  # (1, 1): top-right
        T.mean(axis=(0, 1)),  # centre: mean of the four texels
        (T[0, 0] + T[0, 1]) / 2,  # top edge, halfway
        0.75 * T[1, 0] + 0.25 * T[1, 1],  # bottom row, a quarter of the way
        (T[1, 0] + T[1, 1]) / 2,  # u = 1.5 wraps to 0.5
        0.25 * T[0, 0] + 0.75 * T[0, 1],  # u = -0.25 wraps to 0.75
    ]
    np.testing.assert_allclose(d.colors, expected, atol=1e-7)
    assert d.texture_file == tmp_path / "tex.png"
    np.testing.assert_array_equal(d.faces, [[0, 1, 2]])


def test_sample_texture_matches_brute_force_bilinear():
    rng = np.random.default_rng(1)
    tex = rng.integers(0, 256, size=(7, 5, 3)).astype(np.uint8)
    uv = rng.uniform(0, 1, size=(50, 2))
    got = sample_texture(tex, uv)
    T = tex / 255.0
    for (u, v), g in zip(uv, got, strict=True):
        x, y = u * 4, (1 - v) * 6
        acc = np.zeros(3)
        for yy in range(7):
            for xx in range(5):
                wgt = max(0.0, 1 - abs(x - xx)) * max(0.0, 1 - abs(y - yy))
                acc += wgt * T[yy, xx]
        np.testing.assert_allclose(g, acc, atol=1e-12)


@pytest.mark.parametrize("broken", ["missing", "garbage"])
def test_missing_or_unreadable_texture_warns_once(tmp_path, broken):
    p = _textured_ply(tmp_path, [(0, 0), (1, 0), (0, 1)], write_texture=False)
    if broken == "garbage":
        (tmp_path / "tex.png").write_bytes(b"not a png at all")
    with pytest.warns(UserWarning) as rec:
        d = read_ply(p)
    msgs = [str(w.message) for w in rec if issubclass(w.category, UserWarning)]
    assert len(msgs) == 1 and "tex.png" in msgs[0]
    assert d.colors is None
    assert d.vertices.shape == (3, 3) and d.normals is not None and d.faces.shape == (1, 3)


# ------------------------------------------------------------------------------------------
# malformed files
# ------------------------------------------------------------------------------------------
def _assert_dataset_error(path: Path, *words):
    with pytest.raises(DatasetError) as ei:
        read_ply(path)
    msg = str(ei.value)
    assert str(path) in msg and "\n" not in msg, msg
    for w in words:
        assert w in msg, msg


def test_missing_file(tmp_path):
    _assert_dataset_error(tmp_path / "nope.ply", "not found")


def test_truncated_binary_and_ascii(tmp_path, mesh):
    pts, nrm, col, faces = mesh
    full = write_ply(tmp_path / "full.ply", pts, nrm, col, faces).read_bytes()
    for cut in (len(full) - 7, len(full) - 26 * 13 - 5):  # inside the faces, inside the vertices
        p = tmp_path / f"cut{cut}.ply"
        p.write_bytes(full[:cut])
        _assert_dataset_error(p, "truncated")
    header = ["ply", "format ascii 1.0", "element vertex 3"] + [f"property float {c}" for c in "xyz"] + ["end_header"]
    _assert_dataset_error(_write_bytes(tmp_path / "ta.ply", header, b"0 0 0\n1 1 1\n2 2\n"), "truncated")
    _assert_dataset_error(_write_bytes(tmp_path / "th.ply", header[:-1]), "end_header")


def test_garbage_and_malformed_headers(tmp_path):
    p = tmp_path / "g.ply"
    p.write_bytes(np.random.default_rng(5).integers(0, 256, 300, dtype=np.uint8).tobytes().replace(b"ply", b"xxx"))
    _assert_dataset_error(p, "not a PLY")
    base = ["ply", "format ascii 1.0", "element vertex 1"] + [f"property float {c}" for c in "xyz"]
    bad_fmt = ["ply", "format binary_middle_endian 1.0"] + base[2:] + ["end_header"]
    _assert_dataset_error(_write_bytes(tmp_path / "fmt.ply", bad_fmt, b"0 0 0\n"), "format")
    bad_type = base[:-1] + ["property float128 z", "end_header"]
    _assert_dataset_error(_write_bytes(tmp_path / "typ.ply", bad_type, b"0 0 0\n"), "float128")
    no_vertex = ["ply", "format ascii 1.0", "element point 1", "property float x", "end_header"]
    _assert_dataset_error(_write_bytes(tmp_path / "nov.ply", no_vertex, b"0\n"), "no vertex element")
    _assert_dataset_error(_write_bytes(tmp_path / "noz.ply", base[:-1] + ["end_header"], b"0 0\n"), "'z'")
    _assert_dataset_error(_write_bytes(tmp_path / "nan.ply", base + ["end_header"], b"0 zero 0\n"), "non-numeric")
    idx = base + ["element face 1", "property list uchar int vertex_indices", "end_header"]
    _assert_dataset_error(_write_bytes(tmp_path / "idx.ply", idx, b"0 0 0\n3 0 0 5\n"), "out of range")


# ------------------------------------------------------------------------------------------
# real BOP models
# ------------------------------------------------------------------------------------------
def test_real_ycbv_textured_model_against_models_info():
    models = _data_dir("ycbv_sample", "models")
    info = json.loads((models / "models_info.json").read_text())
    for oid in (1, 13):
        path = models / f"obj_{oid:06d}.ply"
        header = path.read_bytes()[:400].decode("latin-1")
        n_header = int(header.split("element vertex ")[1].split()[0])
        d = read_ply(path)
        assert d.vertices.shape == (n_header, 3)
        lo, size = d.vertices.min(axis=0), np.ptp(d.vertices, axis=0)
        e = info[str(oid)]
        np.testing.assert_allclose(lo, [e["min_x"], e["min_y"], e["min_z"]], atol=1e-3)  # mm
        np.testing.assert_allclose(size, [e["size_x"], e["size_y"], e["size_z"]], atol=1e-3)
        from scipy.spatial import ConvexHull
        from scipy.spatial.distance import pdist

        hull = d.vertices[ConvexHull(d.vertices).vertices]
        assert pdist(hull).max() == pytest.approx(e["diameter"], rel=1e-3)
        assert d.texture_file == models / f"obj_{oid:06d}.png"
        assert d.colors is not None and d.colors.shape == (n_header, 3)
        assert d.colors.min() >= 0 and d.colors.max() <= 1
        assert d.colors.std(axis=0).min() > 0.02  # textured, not constant
        assert len(np.unique(np.round(d.colors, 3), axis=0)) > 100
        assert d.normals is not None and d.faces is not None and d.faces.max() < n_header


def test_real_ycbv_untextured_model():
    models = _data_dir("ycbv_sample", "models")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        d = read_ply(models / "obj_000004.ply")
    assert d.colors is None and d.texture_file is None and d.normals is None
    assert len(d.vertices) > 100 and d.faces.shape[1] == 3


def test_real_models_match_open3d():
    o3d = pytest.importorskip("open3d")
    ycbv = _data_dir("ycbv_sample", "models")
    lmo = _data_dir("lmo", "models")
    # textured binary ycbv model: vertices, normals and triangles
    path = ycbv / "obj_000005.ply"
    d = read_ply(path)
    m = o3d.io.read_triangle_mesh(str(path))
    np.testing.assert_array_equal(d.vertices, np.asarray(m.vertices))
    np.testing.assert_array_equal(d.faces, np.asarray(m.triangles))
    np.testing.assert_allclose(d.normals, np.asarray(m.vertex_normals), atol=1e-6)
    # vertex-coloured ascii LM-O model: vertices and colours
    path = lmo / "obj_000001.ply"
    d = read_ply(path)
    m = o3d.io.read_triangle_mesh(str(path))
    assert d.colors is not None and d.texture_file is None
    np.testing.assert_allclose(d.vertices, np.asarray(m.vertices), rtol=1e-7)
    np.testing.assert_allclose(d.colors, np.asarray(m.vertex_colors), atol=1e-6)
    np.testing.assert_array_equal(d.faces, np.asarray(m.triangles))
    assert d.colors.std(axis=0).min() > 0.01
