"""Objects of a BOP dataset (``<dataset>/models/obj_NNNNNN.ply``) as generator assets.

A BOP model is a PLY mesh in millimetres in the dataset's model frame, coloured by a texture
(``texture_u texture_v`` per vertex and a ``comment TextureFile NAME.png`` header line, the YCB-Video
form), by vertex colours (``red green blue``, most other BOP datasets) or not at all. Drake's
``RenderEngineVtk`` reads Wavefront OBJ meshes with an MTL material whose ``map_Kd`` names a PNG
texture, in whatever unit the file has (metres here). :func:`convert_bop_model` turns one BOP PLY
into that form, keeping the model frame (only the unit changes), so a pose of the converted mesh is a
pose in the BOP model frame; :func:`converted_model` does it once per source content (a cache keyed
by the SHA-256 of the PLY and its texture).

Texture coordinates: BOP (like OBJ and OpenGL) puts v = 0 at the *bottom* row of the texture image,
and OBJ ``vt`` lines use the same convention, so uvs are copied unchanged (no flip); the texture
image is re-encoded as PNG. Vertex colours cannot be given to Drake through an OBJ, so they are
baked into a small texture: every face gets one texel holding the mean colour of its three vertices
and all three corners of the face point at that texel's centre (the face is drawn in one colour; the
models are dense enough that this matches the vertex colours to within a few millimetres). A model
without colours gets a uniform grey texture (:data:`UNTEXTURED_GREY`).

Masses: a BOP object that is a YCB object (through a table of names such as :data:`YCBV_YCB_NAMES`)
takes its mass from the YCB ``objects.csv``; any other object gets :data:`DEFAULT_DENSITY_KG_M3` times
its mesh volume (:func:`model_mass`). Centre of mass and inertia then follow from the mesh as for the
YCB meshes (:func:`sixdpose.assets.ycb.physical_properties`).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .ycb import AssetError, MeshData

#: YCB-Video (BOP ``ycbv``) object ids 1-21 -> YCB names, in the standard order.
YCBV_YCB_NAMES: tuple[str, ...] = (
    "002_master_chef_can", "003_cracker_box", "004_sugar_box", "005_tomato_soup_can", "006_mustard_bottle",
    "007_tuna_fish_can", "008_pudding_box", "009_gelatin_box", "010_potted_meat_can", "011_banana",
    "019_pitcher_base", "021_bleach_cleanser", "024_bowl", "025_mug", "035_power_drill", "036_wood_block",
    "037_scissors", "040_large_marker", "051_large_clamp", "052_extra_large_clamp", "061_foam_brick",
)

#: Known BOP datasets made of YCB objects: name -> obj_id -> YCB name (``GenerationConfig.bop_ycb_map``).
BOP_YCB_MAPS: dict[str, dict[int, str]] = {"ycbv": {k + 1: n for k, n in enumerate(YCBV_YCB_NAMES)}}

#: Density (kg/m^3) of a BOP object that is not a YCB object: mass = density x mesh volume. 600 kg/m^3 is
#: about the median of the YCB objects' mass / closed-mesh volume (629 over the 46 google_16k models).
DEFAULT_DENSITY_KG_M3 = 600.0

#: Fraction of the bounding box taken as the volume when a mesh is not closed (no valid signed volume).
OPEN_MESH_FILL = 0.3

#: RGB in [0, 1] of a model without texture or vertex colours.
UNTEXTURED_GREY = (0.6, 0.6, 0.6)

#: Changes whenever the conversion's output changes, so a stale cache entry is never reused.
CONVERTER_VERSION = "1"

_OBJ_RE = re.compile(r"^obj_(\d{6})\.ply$")


@dataclass(frozen=True)
class BopModel:
    """One model file of a BOP ``models/`` directory.

    Attributes:
        obj_id: BOP object id. name: ``obj_NNNNNN`` (the name BOP readers give it).
        ply_path: the PLY (millimetres). symmetric: ``models_info.json`` has a discrete or continuous
            symmetry for it (False when there is no ``models_info.json``).
    """

    obj_id: int
    name: str
    ply_path: Path
    symmetric: bool


def bop_name(obj_id: int) -> str:
    """The object name of BOP id ``obj_id``: ``obj_NNNNNN`` (as :class:`~sixdpose.datasets.bop.BopDataset` names it)."""
    return f"obj_{int(obj_id):06d}"


def list_bop_models(models_dir: str | os.PathLike) -> dict[int, BopModel]:
    """The models of a BOP ``models/`` directory, by obj_id (``obj_NNNNNN.ply`` files).

    Raises:
        AssetError: the directory does not exist, holds no ``obj_NNNNNN.ply``, or its
            ``models_info.json`` is corrupt.
    """
    d = Path(models_dir).expanduser()
    if not d.is_dir():
        raise AssetError(f"{d}: BOP models directory not found")
    info = {}
    info_path = d / "models_info.json"
    if info_path.is_file():
        from .. import schemas

        try:
            data = json.loads(info_path.read_text())
        except (OSError, UnicodeDecodeError, ValueError) as e:
            raise AssetError(f"{info_path}: corrupt models_info.json ({e})") from None
        info = {int(k): v for k, v in schemas.check(schemas.BOP_MODELS_INFO, data, info_path, AssetError,
                                                    item="object").items()}
    out = {}
    for p in sorted(d.iterdir()):
        m = _OBJ_RE.match(p.name)
        if m:
            oid = int(m.group(1))
            v = info.get(oid)
            sym = v is not None and (bool(v.symmetries_discrete) or bool(v.symmetries_continuous))
            out[oid] = BopModel(oid, bop_name(oid), p.resolve(), sym)
    if not out:
        raise AssetError(f"{d}: no BOP models (obj_NNNNNN.ply) in this directory")
    return out


# ------------------------------------------------------------------------------------------
# conversion
# ------------------------------------------------------------------------------------------
def _read_bop_ply(ply_path: Path):
    import warnings

    from ..datasets.base import DatasetError
    from ..datasets.ply import read_ply

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a missing texture is handled below (grey), not warned twice
            ply = read_ply(ply_path)
    except DatasetError as e:
        raise AssetError(str(e)) from None
    if ply.faces is None or len(ply.faces) == 0:
        raise AssetError(f"{ply_path}: PLY has no faces (a triangle mesh is needed to render the object)")
    return ply


def _texture_png(path: Path) -> bytes | None:
    """The texture image re-encoded as RGB PNG, or None if it is missing or unreadable."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            buf = io.BytesIO()
            im.convert("RGB").save(buf, format="PNG")
            return buf.getvalue()
    except Exception:
        return None


def bake_face_colours(faces: np.ndarray, colors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bake per-vertex colours into a texture with one texel per face.

    Args:
        faces: (F, 3) vertex indices. colors: (V, 3) RGB in [0, 1].
    Returns:
        ``(texture (S, S, 3) uint8, face_uv (F, 2))``: face f is drawn in the mean colour of its three
        vertices, stored in texel ``f`` (row-major from the top-left); ``face_uv[f]`` is that texel's
        centre in OBJ convention (v = 0 at the bottom row). ``S = ceil(sqrt(F))``.
    """
    F = len(faces)
    S = max(1, int(np.ceil(np.sqrt(F))))
    mean = np.asarray(colors, np.float64)[np.asarray(faces)].mean(axis=1)
    tex = np.full((S * S, 3), 0, np.uint8)
    tex[:F] = np.clip(np.round(mean * 255.0), 0, 255).astype(np.uint8)
    row, col = np.divmod(np.arange(F), S)
    uv = np.stack([(col + 0.5) / S, 1.0 - (row + 0.5) / S], axis=1)
    return tex.reshape(S, S, 3), uv


def _png(img: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return buf.getvalue()


def _obj_text(V: np.ndarray, N: np.ndarray, VT: np.ndarray, faces_v: np.ndarray, faces_t: np.ndarray,
              comment: str) -> str:
    lines = [f"# {comment}", "mtllib textured.mtl", "usemtl material_0"]
    out = io.StringIO()
    out.write("\n".join(lines) + "\n")
    np.savetxt(out, V, fmt="v %.9g %.9g %.9g")
    np.savetxt(out, VT, fmt="vt %.9g %.9g")
    np.savetxt(out, N, fmt="vn %.6g %.6g %.6g")
    f = np.empty((len(faces_v), 9), np.int64)
    f[:, 0::3] = faces_v + 1
    f[:, 1::3] = faces_t + 1
    f[:, 2::3] = faces_v + 1
    np.savetxt(out, f, fmt="f %d/%d/%d %d/%d/%d %d/%d/%d")
    return out.getvalue()


def convert_bop_model(ply_path: str | os.PathLike, out_dir: str | os.PathLike) -> Path:
    """Convert one BOP PLY model into ``out_dir/{textured.obj, textured.mtl, texture_map.png}`` (metres).

    The layout and unit are those of the YCB google_16k meshes, so the converted model goes wherever a
    YCB mesh does (:func:`sixdpose.assets.ycb.load_mesh`, Drake's ``Mesh``). Vertices are divided by
    1000 (mm -> m) and nothing else changes: the OBJ frame is the BOP model frame. Colour: the PLY's
    texture (uvs copied, v = 0 at the bottom as in OBJ), else its vertex colours baked into one texel
    per face (:func:`bake_face_colours`), else a uniform grey. Normals: the PLY's, else area-weighted
    vertex normals. Files are written into a temporary directory which then becomes ``out_dir``.

    Args:
        ply_path: BOP model (``obj_NNNNNN.ply``, millimetres).
        out_dir: directory to create (must not exist).
    Returns:
        the path of ``textured.obj``.
    Raises:
        AssetError: the PLY is missing, malformed or has no faces.
    """
    from ..datasets.ply import vertex_normals

    ply_path, out_dir = Path(ply_path), Path(out_dir)
    ply = _read_bop_ply(ply_path)
    V = ply.vertices / 1000.0
    faces = ply.faces.astype(np.int64)
    N = ply.normals if ply.normals is not None else vertex_normals(V, faces)
    N = N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-12)
    tex_png = None
    if ply.uvs is not None and ply.texture_file is not None:
        tex_png = _texture_png(ply.texture_file)
    if tex_png is not None:
        how = f"texture {ply.texture_file.name}"
        VT, faces_t = ply.uvs, faces
    elif ply.colors is not None:
        how = "vertex colours baked into one texel per face"
        tex, VT = bake_face_colours(faces, ply.colors)
        tex_png, faces_t = _png(tex), np.repeat(np.arange(len(faces))[:, None], 3, axis=1)
    else:
        how = "no colour in the PLY: uniform grey"
        tex_png = _png(np.full((2, 2, 3), np.round(np.array(UNTEXTURED_GREY) * 255), np.uint8))
        VT, faces_t = np.array([[0.5, 0.5]]), np.zeros_like(faces)
    comment = f"sixdpose {CONVERTER_VERSION}: {ply_path.name} in metres (BOP model frame); {how}"
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=out_dir.parent))
    os.chmod(tmp, 0o755)
    try:
        (tmp / "texture_map.png").write_bytes(tex_png)
        (tmp / "textured.mtl").write_text("newmtl material_0\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nmap_Kd texture_map.png\n")
        (tmp / "textured.obj").write_text(_obj_text(V, N, VT, faces, faces_t, comment))
        os.replace(tmp, out_dir)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out_dir / "textured.obj"


def source_digest(ply_path: str | os.PathLike) -> str:
    """SHA-256 (hex) of a BOP model's content: the PLY bytes, its texture's bytes (when the header
    names one that exists) and :data:`CONVERTER_VERSION`.

    Raises:
        AssetError: the PLY cannot be read.
    """
    from ..datasets.ply import read_ply_header_comments

    p = Path(ply_path)
    h = hashlib.sha256(f"sixdpose-bop-converter {CONVERTER_VERSION}\n".encode())
    try:
        data = p.read_bytes()
    except OSError as e:
        raise AssetError(f"{p}: cannot read BOP model ({e.strerror or e})") from None
    h.update(data)
    tex = read_ply_header_comments(data, "TextureFile")
    if tex and (p.parent / tex).is_file():
        h.update(b"\0texture\0")
        h.update((p.parent / tex).read_bytes())
    return h.hexdigest()


def default_cache_dir() -> Path:
    """Where converted models are kept: ``$SIXDPOSE_CACHE/bop_models`` or
    ``${XDG_CACHE_HOME:-~/.cache}/sixdpose/bop_models``."""
    root = os.environ.get("SIXDPOSE_CACHE")
    if root:
        return Path(root).expanduser() / "bop_models"
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache").expanduser() / "sixdpose" / "bop_models"


def converted_model(ply_path: str | os.PathLike, cache_dir: str | os.PathLike | None = None) -> tuple[Path, str]:
    """The converted OBJ of a BOP model, converting it the first time its content is seen.

    Args:
        ply_path: BOP model. cache_dir: cache root (default :func:`default_cache_dir`).
    Returns:
        ``(path of textured.obj, source SHA-256)``; the entry is ``<cache>/<first 24 hex digits>/``.
    Raises:
        AssetError: unreadable PLY, no faces, or an unwritable cache.
    """
    digest = source_digest(ply_path)
    d = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    entry = d / digest[:24]
    obj = entry / "textured.obj"
    if obj.is_file():
        return obj, digest
    try:
        convert_bop_model(ply_path, entry)
    except OSError as e:
        if obj.is_file():  # another process converted it meanwhile
            return obj, digest
        raise AssetError(f"{entry}: cannot write the converted model ({e.strerror or e})") from None
    return obj, digest


def mesh_volume(mesh: MeshData) -> float:
    """Volume (m^3) of a mesh: its signed volume when that is a valid closed-surface value (more than
    1e-3 of the bounding box, the test :func:`~sixdpose.assets.ycb.physical_properties` uses), else
    :data:`OPEN_MESH_FILL` times the bounding-box volume."""
    V, F = mesh.vertices, mesh.faces
    a, b, c = (V[F[:, k]] for k in range(3))
    vol = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)
    box = float(np.prod(np.maximum(V.max(0) - V.min(0), 1e-6)))
    return vol if vol > 1e-3 * box else OPEN_MESH_FILL * box


def model_mass(mesh: MeshData, ycb_mass: float | None = None, density: float = DEFAULT_DENSITY_KG_M3) -> float:
    """Mass (kg) of a converted BOP model: ``ycb_mass`` (from ``objects.csv``) when the object is a YCB
    object, else ``density`` (kg/m^3) x :func:`mesh_volume` (at least 1 g)."""
    if ycb_mass is not None:
        return float(ycb_mass)
    return max(float(density) * mesh_volume(mesh), 1e-3)


#: Environment variable naming the default BOP models directory (``--assets-bop``).
BOP_ENV_VAR = "SIXDPOSE_BOP_MODELS"


def resolve_bop_models_dir(path: str | os.PathLike | None = None, ycb_map: str | None = None) -> Path:
    """The BOP models directory: ``path`` if given, else ``$SIXDPOSE_BOP_MODELS``, else (for
    ``ycb_map == "ycbv"``) ``../shared/data/ycbv_sample/models`` beside the repository when it exists.

    Raises:
        AssetError: none given or found, or the directory does not exist.
    """
    if path is None:
        path = os.environ.get(BOP_ENV_VAR) or None
    if path is None and ycb_map == "ycbv":
        cand = Path(__file__).resolve().parents[4] / "shared" / "data" / "ycbv_sample" / "models"
        if cand.is_dir():
            return cand
    if path is None:
        raise AssetError(f"no BOP models directory: pass --assets-bop DIR/models or set {BOP_ENV_VAR}")
    p = Path(path).expanduser()
    if not p.is_dir():
        raise AssetError(f"{p}: BOP models directory not found")
    return p.resolve()
