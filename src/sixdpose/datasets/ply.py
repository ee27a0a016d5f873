"""PLY model reader/writer (pure numpy) that understands textured BOP models.

BOP models (Hodaň et al. 2018, "BOP: Benchmark for 6D object pose estimation", ECCV) are PLY meshes
in millimetres. Most carry per-vertex colours (``red green blue``); the YCB-Video models are
*textured*: per-vertex ``texture_u texture_v`` plus a header line ``comment TextureFile NAME.png``
naming a texture image that lies beside the PLY. :func:`read_ply` turns both into per-vertex
colours, so every later stage sees the same :class:`PlyData`.

Supported: ``ascii 1.0``, ``binary_little_endian 1.0`` and ``binary_big_endian 1.0``; every PLY
scalar type (``char uchar short ushort int uint float double`` and the ``int8 uint8 int16 uint16
int32 uint32 float32 float64`` spellings); any element (unknown elements are read past and
dropped); list properties (a face element ``property list <count type> <index type>
vertex_indices``, or ``vertex_index``). Polygons are fan-triangulated (a quad ``a b c d`` becomes
``a b c`` and ``a c d``); rows with fewer than 3 indices are dropped. Not supported: per-face
("wedge") texture coordinates (``property list ... texcoord``) -- such a model is read without
colours.

Units are those of the file (BOP: millimetres); callers convert to metres.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..fileio import atomic_write_bytes
from .base import DatasetError

__all__ = ["PlyData", "read_ply", "write_ply", "sample_texture", "read_ply_header_comments"]

# PLY scalar type name -> numpy type code (without byte order)
_PLY_TYPES = {
    "char": "i1", "int8": "i1",
    "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4",
    "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4",
    "double": "f8", "float64": "f8",
}
_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
_FACE_LISTS = ("vertex_indices", "vertex_index")
_COLOR_NAMES = (("red", "green", "blue"), ("diffuse_red", "diffuse_green", "diffuse_blue"))
_UV_NAMES = (("texture_u", "texture_v"), ("s", "t"), ("u", "v"))


@dataclass(frozen=True, eq=False)
class PlyData:
    """Contents of a PLY model.

    Attributes:
        vertices: (N, 3) float64 vertex positions, in the file's units (BOP: millimetres).
        normals: (N, 3) float64 vertex normals as stored (not re-normalised), or ``None``.
        colors: (N, 3) float64 RGB in [0, 1] -- from ``red/green/blue`` (integer types divided by
            the type's maximum, e.g. uchar / 255; float kept as stored) or sampled from the texture
            of a textured model -- or ``None``.
        faces: (F, 3) int64 triangle vertex indices (polygons fan-triangulated), or ``None`` if the
            file has no face element.
        texture_file: path of the texture named by ``comment TextureFile`` (resolved beside the
            PLY), whether or not it could be read; ``None`` if the header names none.
        uvs: (N, 2) float64 per-vertex texture coordinates as stored (``texture_u texture_v``, ``s t``
            or ``u v``; OBJ/OpenGL convention, v = 0 is the bottom row of the texture), or ``None``.
    """

    vertices: np.ndarray
    normals: np.ndarray | None = None
    colors: np.ndarray | None = None
    faces: np.ndarray | None = None
    texture_file: Path | None = None
    uvs: np.ndarray | None = None


@dataclass
class _Prop:
    name: str
    dtype: str  # numpy type code without byte order, e.g. "f4"
    count_dtype: str | None = None  # list properties only


@dataclass
class _Element:
    name: str
    count: int
    props: list[_Prop]


# ------------------------------------------------------------------------------------------
# header
# ------------------------------------------------------------------------------------------
def _parse_header(path: Path, raw: bytes) -> tuple[str, list[_Element], list[str], int]:
    """Return (format, elements, comments, offset of the first data byte)."""
    if not raw.startswith(b"ply"):
        raise DatasetError(f"{path}: not a PLY file (no 'ply' magic line)")
    end = raw.find(b"end_header")
    if end < 0:
        raise DatasetError(f"{path}: malformed PLY header (no 'end_header' line)")
    nl = raw.find(b"\n", end)
    if nl < 0:
        # "end_header" as the very last bytes: the header is complete, the data is empty
        nl = len(raw) - 1
    data_start = nl + 1
    lines = raw[:end].decode("latin-1").splitlines()
    if lines[0].strip() != "ply":
        raise DatasetError(f"{path}: not a PLY file (first line {lines[0].strip()[:40]!r}, expected 'ply')")
    fmt = None
    elements: list[_Element] = []
    comments: list[str] = []
    for lineno, line in enumerate(lines[1:], start=2):
        tok = line.split()
        if not tok:
            continue
        kw = tok[0]
        try:
            if kw == "format":
                if len(tok) < 2 or tok[1] not in _FORMATS:
                    raise DatasetError(f"{path}: unknown PLY format {' '.join(tok[1:])!r}")
                fmt = tok[1]
            elif kw == "comment":
                comments.append(line.strip()[len("comment"):].strip())
            elif kw == "obj_info":
                continue
            elif kw == "element":
                if len(tok) != 3:
                    raise ValueError("expected 'element <name> <count>'")
                count = int(tok[2])
                if count < 0:
                    raise ValueError("negative element count")
                elements.append(_Element(tok[1], count, []))
            elif kw == "property":
                if not elements:
                    raise ValueError("property before any element")
                if len(tok) >= 2 and tok[1] == "list":
                    if len(tok) != 5:
                        raise ValueError("expected 'property list <count type> <item type> <name>'")
                    ct, it = _ply_type(tok[2]), _ply_type(tok[3])
                    if ct[0] == "f":
                        raise ValueError(f"list count type {tok[2]!r} is not an integer type")
                    elements[-1].props.append(_Prop(tok[4], it, ct))
                else:
                    if len(tok) != 3:
                        raise ValueError("expected 'property <type> <name>'")
                    elements[-1].props.append(_Prop(tok[2], _ply_type(tok[1])))
            else:
                raise ValueError(f"unknown keyword {kw!r}")
        except ValueError as e:
            raise DatasetError(f"{path}: malformed PLY header line {lineno} {line.strip()[:60]!r} ({e})") from None
    if fmt is None:
        raise DatasetError(f"{path}: malformed PLY header (no 'format' line)")
    return fmt, elements, comments, data_start


def _ply_type(name: str) -> str:
    try:
        return _PLY_TYPES[name]
    except KeyError:
        raise ValueError(f"unknown property type {name!r}") from None


# ------------------------------------------------------------------------------------------
# data
# ------------------------------------------------------------------------------------------
def _read_binary_element(path: Path, buf: bytes, off: int, el: _Element, bo: str):
    """Parse one element of a binary body starting at byte ``off``.

    Returns (columns: name -> ndarray (count,) for scalars, (count, k) or list of arrays for lists,
    new offset).
    """
    n = el.count
    if n == 0:
        return {p.name: np.zeros((0,) if p.count_dtype is None else (0, 0), p.dtype) for p in el.props}, off
    lists = [p for p in el.props if p.count_dtype is not None]
    # fast path: guess the list lengths from the first row, read every row with one structured
    # dtype and check the guess (if every row's count field equals the guess, the parse is exact)
    guess: dict[str, int] = {}
    pos = off
    for p in el.props:
        if p.count_dtype is None:
            pos += np.dtype(p.dtype).itemsize
            continue
        csize = np.dtype(p.count_dtype).itemsize
        if pos + csize > len(buf):
            raise DatasetError(f"{path}: truncated data in element {el.name!r} (file ends at byte {len(buf)})")
        k = int(np.frombuffer(buf, bo + p.count_dtype, 1, pos)[0])
        if k < 0:
            raise DatasetError(f"{path}: negative list length in element {el.name!r}")
        guess[p.name] = k
        pos += csize + k * np.dtype(p.dtype).itemsize
    fields = []
    for i, p in enumerate(el.props):
        if p.count_dtype is None:
            fields.append((f"f{i}", bo + p.dtype))
        else:
            fields.append((f"c{i}", bo + p.count_dtype))
            fields.append((f"f{i}", bo + p.dtype, (guess[p.name],)))
    dt = np.dtype(fields)
    need = n * dt.itemsize
    if len(buf) - off >= need:
        rows = np.frombuffer(buf, dt, n, off)
        if all(np.all(rows[f"c{i}"] == guess[p.name]) for i, p in enumerate(el.props) if p.count_dtype is not None):
            cols = {p.name: np.ascontiguousarray(rows[f"f{i}"]) for i, p in enumerate(el.props)}
            return cols, off + need
    elif not lists:
        raise DatasetError(f"{path}: truncated data in element {el.name!r} (needs {need} bytes, {len(buf) - off} left)")
    # slow path: variable list lengths, row by row
    cols_l: dict[str, list] = {p.name: [] for p in el.props}
    pos = off
    for _ in range(n):
        for p in el.props:
            if p.count_dtype is None:
                size = np.dtype(p.dtype).itemsize
                if pos + size > len(buf):
                    raise DatasetError(f"{path}: truncated data in element {el.name!r} (file ends at byte {len(buf)})")
                cols_l[p.name].append(np.frombuffer(buf, bo + p.dtype, 1, pos)[0])
                pos += size
            else:
                csize = np.dtype(p.count_dtype).itemsize
                if pos + csize > len(buf):
                    raise DatasetError(f"{path}: truncated data in element {el.name!r} (file ends at byte {len(buf)})")
                k = int(np.frombuffer(buf, bo + p.count_dtype, 1, pos)[0])
                pos += csize
                size = k * np.dtype(p.dtype).itemsize
                if k < 0 or pos + size > len(buf):
                    raise DatasetError(f"{path}: truncated data in element {el.name!r} (file ends at byte {len(buf)})")
                cols_l[p.name].append(np.frombuffer(buf, bo + p.dtype, k, pos))
                pos += size
    cols = {p.name: (np.asarray(cols_l[p.name]) if p.count_dtype is None else cols_l[p.name]) for p in el.props}
    return cols, pos


def _read_ascii_element(path: Path, vals: np.ndarray, pos: int, el: _Element):
    """Parse one element from the flat float64 array of all ascii tokens, starting at ``pos``."""
    n = el.count
    if n == 0:
        return {p.name: np.zeros((0,) if p.count_dtype is None else (0, 0), p.dtype) for p in el.props}, pos

    def truncated():
        return DatasetError(f"{path}: truncated data in element {el.name!r} ({len(vals) - pos} values left)")

    guess: dict[str, int] = {}
    width = 0
    for p in el.props:
        if p.count_dtype is None:
            width += 1
        else:
            if pos + width >= len(vals):
                raise truncated()
            k = vals[pos + width]
            if k < 0 or k != int(k):
                raise DatasetError(f"{path}: bad list length {k!r} in element {el.name!r}")
            guess[p.name] = int(k)
            width += 1 + int(k)
    if pos + n * width <= len(vals):
        rows = vals[pos: pos + n * width].reshape(n, width)
        cols, c, ok = {}, 0, True
        for p in el.props:
            if p.count_dtype is None:
                cols[p.name] = rows[:, c]
                c += 1
            else:
                k = guess[p.name]
                if not np.all(rows[:, c] == k):
                    ok = False
                    break
                cols[p.name] = rows[:, c + 1: c + 1 + k]
                c += 1 + k
        if ok:
            return {p.name: cols[p.name].astype(p.dtype) for p in el.props}, pos + n * width
    elif not guess:
        raise truncated()
    cols_l: dict[str, list] = {p.name: [] for p in el.props}
    for _ in range(n):
        for p in el.props:
            if pos >= len(vals):
                raise truncated()
            if p.count_dtype is None:
                cols_l[p.name].append(vals[pos])
                pos += 1
            else:
                k = vals[pos]
                if k < 0 or k != int(k):
                    raise DatasetError(f"{path}: bad list length {k!r} in element {el.name!r}")
                k = int(k)
                if pos + 1 + k > len(vals):
                    raise truncated()
                cols_l[p.name].append(vals[pos + 1: pos + 1 + k].astype(p.dtype))
                pos += 1 + k
    cols = {
        p.name: (np.asarray(cols_l[p.name], dtype=p.dtype) if p.count_dtype is None else cols_l[p.name])
        for p in el.props
    }
    return cols, pos


def _triangulate(rows) -> np.ndarray:
    """(F, k) array or list of 1-D index arrays -> (T, 3) int64 triangles (fan triangulation)."""
    if isinstance(rows, np.ndarray):
        rows = rows.astype(np.int64, copy=False)
        k = rows.shape[1]
        if k < 3:
            return np.zeros((0, 3), np.int64)
        if k == 3:
            return np.ascontiguousarray(rows)
        tris = np.stack([np.stack([rows[:, 0], rows[:, j], rows[:, j + 1]], axis=1) for j in range(1, k - 1)], axis=1)
        return tris.reshape(-1, 3)
    out = [(int(r[0]), int(r[j]), int(r[j + 1])) for r in rows for j in range(1, len(r) - 1)]
    return np.asarray(out, dtype=np.int64).reshape(-1, 3)


def _unit_colors(cols: list[np.ndarray]) -> np.ndarray:
    """Colour columns -> (N, 3) float64 in [0, 1] (integer types divided by the type maximum)."""
    out = []
    for c in cols:
        if np.issubdtype(c.dtype, np.integer):
            out.append(c.astype(np.float64) / float(np.iinfo(c.dtype).max))
        else:
            out.append(c.astype(np.float64))
    return np.stack(out, axis=1)


def sample_texture(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinearly sample a texture image at per-vertex texture coordinates.

    Convention (OBJ/OpenGL): ``v = 0`` is the *bottom* row of the image; ``(u, v)`` maps to the
    continuous pixel position ``(x, y) = (u * (W - 1), (1 - v) * (H - 1))`` with pixel centres at
    integer coordinates. Coordinates outside [0, 1] wrap (repeat); NaN is read as 0.

    Args:
        texture: (H, W, C) or (H, W) image; integer types are divided by the type maximum
            (uint8 / 255), float images are used as they are.
        uv: (N, 2) texture coordinates.
    Returns:
        (N, C) float64 sampled values ((N, 1) for a single-channel image).
    """
    tex = np.asarray(texture)
    if tex.ndim == 2:
        tex = tex[..., None]
    if np.issubdtype(tex.dtype, np.integer):
        tex = tex.astype(np.float64) / float(np.iinfo(tex.dtype).max)
    else:
        tex = tex.astype(np.float64)
    h, w = tex.shape[:2]
    uv = np.nan_to_num(np.asarray(uv, dtype=np.float64).reshape(-1, 2), nan=0.0, posinf=0.0, neginf=0.0)
    uv = np.where((uv < 0.0) | (uv > 1.0), uv - np.floor(uv), uv)
    x = np.clip(uv[:, 0], 0.0, 1.0) * (w - 1)
    y = (1.0 - np.clip(uv[:, 1], 0.0, 1.0)) * (h - 1)
    x0 = np.floor(x).astype(np.int64)
    y0 = np.floor(y).astype(np.int64)
    x1 = np.minimum(x0 + 1, w - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    wx = (x - x0)[:, None]
    wy = (y - y0)[:, None]
    return (
        tex[y0, x0] * (1 - wx) * (1 - wy)
        + tex[y0, x1] * wx * (1 - wy)
        + tex[y1, x0] * (1 - wx) * wy
        + tex[y1, x1] * wx * wy
    )


def _texture_name(comments: list[str]) -> str | None:
    for c in comments:
        tok = c.split(None, 1)
        if tok and tok[0].lower() == "texturefile" and len(tok) == 2:
            return tok[1].strip()
    return None


def read_ply_header_comments(raw: bytes, key: str) -> str | None:
    """The value of the first header line ``comment <key> <value>`` of PLY bytes ``raw`` (``key``
    compared case-insensitively, e.g. ``"TextureFile"``), or ``None`` if the header has none."""
    end = raw.find(b"end_header")
    head = raw[: end if end >= 0 else min(len(raw), 65536)].decode("latin-1")
    for line in head.splitlines():
        tok = line.strip().split(None, 2)
        if len(tok) == 3 and tok[0] == "comment" and tok[1].lower() == key.lower():
            return tok[2].strip()
    return None


def read_ply(path: str | Path) -> PlyData:
    """Read a PLY point cloud or triangle mesh (pure numpy, no Open3D).

    Colours come from ``red/green/blue`` vertex properties if present, else -- for a textured model
    with per-vertex ``texture_u/texture_v`` and a header line ``comment TextureFile NAME`` -- from
    the texture image ``NAME`` beside the PLY, sampled bilinearly (see :func:`sample_texture`; v = 0
    is the bottom row of the image). A missing or unreadable texture gives one warning
    (``UserWarning`` naming the texture file) and ``colors=None``, never an exception.

    Args:
        path: the ``.ply`` file (ascii, binary_little_endian or binary_big_endian).
    Returns:
        :class:`PlyData` with vertices (N, 3) float64 in the file's units (BOP: mm), normals,
        colours in [0, 1], faces (F, 3) int64, the texture path and the per-vertex uvs.
    Raises:
        DatasetError: one line naming the file: missing file, not a PLY, malformed header, unknown
            format or type, no vertex element, no x/y/z, truncated data, non-numeric ascii data,
            face index out of range.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise DatasetError(f"{path}: file not found") from None
    except OSError as e:
        raise DatasetError(f"{path}: unreadable ({e.strerror or e})") from None
    fmt, elements, comments, data_start = _parse_header(path, raw)
    names = [e.name for e in elements]
    if "vertex" not in names:
        raise DatasetError(f"{path}: no vertex element in the PLY header")
    data: dict[str, dict] = {}
    if fmt == "ascii":
        try:
            vals = np.array(raw[data_start:].split(), dtype=np.float64)
        except ValueError:
            raise DatasetError(f"{path}: non-numeric value in the ascii data") from None
        pos = 0
        for el in elements:
            cols, pos = _read_ascii_element(path, vals, pos, el)
            data.setdefault(el.name, cols)
    else:
        bo = _FORMATS[fmt]
        off = data_start
        for el in elements:
            cols, off = _read_binary_element(path, raw, off, el, bo)
            data.setdefault(el.name, cols)

    vert = data["vertex"]
    vprops = {p.name: p for p in elements[names.index("vertex")].props}
    for c in ("x", "y", "z"):
        if c not in vert or vprops[c].count_dtype is not None:
            raise DatasetError(f"{path}: vertex element has no scalar property {c!r}")
    vertices = np.stack([vert[c] for c in "xyz"], axis=1).astype(np.float64)
    n = len(vertices)
    normals = None
    if all(c in vert and vprops[c].count_dtype is None for c in ("nx", "ny", "nz")):
        normals = np.stack([vert[c] for c in ("nx", "ny", "nz")], axis=1).astype(np.float64)
    colors = None
    for cn in _COLOR_NAMES:
        if all(c in vert and vprops[c].count_dtype is None for c in cn):
            colors = _unit_colors([vert[c] for c in cn])
            break
    texture_file = None
    tex_name = _texture_name(comments)
    if tex_name is not None:
        texture_file = path.parent / tex_name
    uvn = next((cn for cn in _UV_NAMES if all(c in vert and vprops[c].count_dtype is None for c in cn)), None)
    uvs = None if uvn is None else np.stack([vert[uvn[0]], vert[uvn[1]]], axis=1).astype(np.float64)
    if colors is None and texture_file is not None and uvs is not None:
        tex = _load_texture(texture_file, path)
        if tex is not None:
            colors = sample_texture(tex, uvs)[:, :3]
    faces = None
    if "face" in data:
        fprops = elements[names.index("face")].props
        lp = next((p for p in fprops if p.name in _FACE_LISTS and p.count_dtype is not None), None)
        if lp is None:
            raise DatasetError(f"{path}: face element has no 'vertex_indices' list property")
        faces = _triangulate(data["face"][lp.name])
        if len(faces) and (faces.min() < 0 or faces.max() >= n):
            raise DatasetError(
                f"{path}: face vertex index out of range [0, {n}) (min {faces.min()}, max {faces.max()})"
            )
    return PlyData(vertices, normals, colors, faces, texture_file, uvs)


def _load_texture(texture_file: Path, ply_path: Path) -> np.ndarray | None:
    """Read a texture as (H, W, 3) uint8, or warn once and return None."""
    from PIL import Image

    try:
        with Image.open(texture_file) as im:
            return np.asarray(im.convert("RGB")).copy()
    except Exception as e:  # missing, truncated, not an image ...
        reason = "file not found" if isinstance(e, FileNotFoundError) else f"unreadable ({type(e).__name__}: {e})"
        warnings.warn(
            f"{texture_file}: texture of {ply_path.name} {reason}; the model is read without colours",
            UserWarning,
            stacklevel=3,
        )
        return None


# ------------------------------------------------------------------------------------------
# writer
# ------------------------------------------------------------------------------------------
def write_ply(path: str | Path, points, normals=None, colors=None, faces=None,
              comment: str = "written by sixdpose") -> Path:
    """Write a binary little-endian PLY (point cloud or triangle mesh), atomically.

    Layout: ``x y z`` float32, optional ``nx ny nz`` float32, optional ``red green blue`` uchar,
    optional ``element face`` with ``property list uchar int vertex_indices``. The file is written
    to a temporary file in the same directory and moved into place with ``os.replace``, so readers
    never see a partial file. Round-trips with :func:`read_ply` within float32 precision (colours
    within 1/255).

    Args:
        path: output ``.ply`` path (its directory must exist).
        points: (N, 3) vertex positions (any unit; BOP models are in mm).
        normals: optional (N, 3) normals.
        colors: optional (N, 3) colours: float in [0, 1] (rounded to uchar, clipped) or uint8.
        faces: optional (F, 3) integer triangle indices in [0, N).
        comment: the header's ``comment`` line.
    Returns:
        The written path.
    Raises:
        ValueError: wrong shapes, non-finite points or face indices out of range.
    """
    path = Path(path)
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points contain NaN or inf")
    n = len(pts)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if normals is not None:
        nrm = np.asarray(normals, dtype=np.float64)
        if nrm.shape != (n, 3):
            raise ValueError(f"normals must have shape ({n}, 3), got {nrm.shape}")
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    if colors is not None:
        col = np.asarray(colors)
        if col.shape != (n, 3):
            raise ValueError(f"colors must have shape ({n}, 3), got {col.shape}")
        if col.dtype == np.uint8:
            c8 = col
        else:
            c8 = np.clip(np.round(np.nan_to_num(col.astype(np.float64)) * 255.0), 0, 255).astype(np.uint8)
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    arr = np.empty(n, dtype=fields)
    arr["x"], arr["y"], arr["z"] = pts.T
    if normals is not None:
        arr["nx"], arr["ny"], arr["nz"] = nrm.T
    if colors is not None:
        arr["red"], arr["green"], arr["blue"] = c8.T
    types = {"<f4": "float", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", f"comment {comment}", f"element vertex {n}"]
    header += [f"property {types[t]} {name}" for name, t in fields]
    fbytes = b""
    if faces is not None:
        f = np.asarray(faces)
        if f.ndim != 2 or f.shape[1] != 3 or (f.size and not np.issubdtype(f.dtype, np.integer)):
            raise ValueError(f"faces must be an integer array of shape (F, 3), got {f.shape} {f.dtype}")
        if f.size and (f.min() < 0 or f.max() >= n):
            raise ValueError(f"face indices must lie in [0, {n})")
        farr = np.empty(len(f), dtype=[("n", "u1"), ("v", "<i4", (3,))])
        farr["n"] = 3
        farr["v"] = f
        header += [f"element face {len(f)}", "property list uchar int vertex_indices"]
        fbytes = farr.tobytes()
    header += ["end_header"]
    atomic_write_bytes(path, ("\n".join(header) + "\n").encode("ascii") + arr.tobytes() + fbytes)
    return path


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (N, 3), unit length (zero for vertices on no face).

    Args:
        vertices: (N, 3) positions. faces: (F, 3) triangle indices (counter-clockwise = outward).
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # length = 2 x area
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, f[:, k], fn)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
