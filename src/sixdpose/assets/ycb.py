"""YCB models in the official layout ``<root>/<name>/google_16k/{textured.obj,textured.mtl,texture_map.png}``
plus ``<root>/objects.csv`` (``name,mass_kg,role,symmetric``).

Units: metres, kilograms. Mesh frames are the original YCB frames (not re-centred); the body frame
of a simulated object is its mesh frame, so ground-truth poses map model points directly.
"""

from __future__ import annotations

import csv
import functools
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SixdposeError

ENV_VAR = "SIXDPOSE_YCB"
MESH_SUBDIR = "google_16k"


class AssetError(SixdposeError):
    """The asset directory, ``objects.csv`` or a model file is missing or malformed."""


@dataclass(frozen=True)
class YcbObject:
    """One catalogue entry of ``objects.csv``.

    Attributes:
        name: YCB name, e.g. ``"006_mustard_bottle"``.
        mass: mass in kg.
        symmetric: whether the object is evaluated with ADD-S (the paper's starred objects); the one
            source of this flag (written to every dataset's ``models_info.yml``).
        mesh_dir: directory holding ``textured.obj`` etc.

    The ``role`` column of ``objects.csv`` is informational: which objects are targets is the
    generator's choice (:data:`sixdpose.constants.TARGET_OBJECTS` for the paper's dataset).
    """

    name: str
    mass: float
    symmetric: bool
    mesh_dir: Path

    @property
    def obj_path(self) -> Path:
        """Path of the textured OBJ mesh."""
        return self.mesh_dir / "textured.obj"


def _repo_default() -> Path | None:
    # <repo>/src/sixdpose/assets/ycb.py -> <repo>/../shared/data/ycb
    cand = Path(__file__).resolve().parents[4] / "shared" / "data" / "ycb"
    return cand if cand.is_dir() else None


def resolve_assets_dir(assets: str | os.PathLike | None = None) -> Path:
    """Return the YCB asset directory: ``assets`` if given, else ``$SIXDPOSE_YCB``, else
    ``../shared/data/ycb`` beside the repository when it exists.

    Raises:
        AssetError: no directory given/found, or it does not exist.
    """
    if assets is None:
        env = os.environ.get(ENV_VAR)
        if env:
            assets = env
        else:
            found = _repo_default()
            if found is None:
                raise AssetError(f"no YCB asset directory: pass --assets DIR or set {ENV_VAR}")
            return found
    p = Path(assets).expanduser()
    if not p.is_dir():
        raise AssetError(f"{p}: YCB asset directory not found")
    return p.resolve()


@functools.lru_cache(maxsize=8)
def load_catalog(root: str | os.PathLike) -> dict[str, YcbObject]:
    """Read ``objects.csv`` of an asset directory and check every listed model exists.

    Returns:
        name -> :class:`YcbObject`, in file order.
    Raises:
        AssetError: missing/corrupt ``objects.csv``, bad field, or a listed model without mesh files.
    """
    root = Path(root)
    csv_path = root / "objects.csv"
    if not csv_path.is_file():
        raise AssetError(f"{csv_path}: not found (the asset directory needs objects.csv)")
    out: dict[str, YcbObject] = {}
    with open(csv_path, newline="") as f:
        reader = csv.DictReader(f)
        need = {"name", "mass_kg", "symmetric"}
        if reader.fieldnames is None or not need <= set(reader.fieldnames):
            raise AssetError(f"{csv_path}: header must contain {sorted(need)}")
        for line, row in enumerate(reader, start=2):
            name = (row["name"] or "").strip()
            try:
                mass = float(row["mass_kg"])
                if not mass > 0:
                    raise ValueError("mass must be positive")
                sym = bool(int(row["symmetric"]))
            except (TypeError, ValueError) as e:
                raise AssetError(f"{csv_path}:{line}: bad mass_kg/symmetric for {name!r} ({e})") from None
            obj = YcbObject(name, mass, sym, root / name / MESH_SUBDIR)
            for fname in ("textured.obj", "texture_map.png"):
                if not (obj.mesh_dir / fname).is_file():
                    raise AssetError(f"{obj.mesh_dir / fname}: missing model file for {name}")
            out[name] = obj
    if not out:
        raise AssetError(f"{csv_path}: lists no objects")
    return out


@dataclass
class MeshData:
    """A triangle mesh with per-corner texture coordinates.

    Attributes:
        vertices: (V, 3) float64 metres.
        faces: (F, 3) int vertex indices.
        face_uvs: (F, 3, 2) float64 texture coordinates of each face corner, or ``None``.
        texture: (H, W, 3) uint8 texture image, or ``None``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_uvs: np.ndarray | None
    texture: np.ndarray | None


@functools.lru_cache(maxsize=64)
def load_mesh(obj_path: str | os.PathLike, with_texture: bool = True) -> MeshData:
    """Parse a Wavefront OBJ (triangles, ``v``/``vt`` and ``f a/b/c``) and its ``texture_map.png``.

    Raises:
        AssetError: the file is missing or malformed.
    """
    obj_path = Path(obj_path)
    try:
        text = obj_path.read_text()
    except OSError as e:
        raise AssetError(f"{obj_path}: cannot read mesh ({e.strerror})") from None
    v, vt, f_v, f_t = [], [], [], []
    try:
        for line in text.splitlines():
            if line.startswith("v "):
                v.append(line[2:].split()[:3])
            elif line.startswith("vt "):
                vt.append(line[3:].split()[:2])
            elif line.startswith("f "):
                corners = line[2:].split()
                if len(corners) < 3:
                    raise ValueError(f"face with {len(corners)} corners")
                idx = [c.split("/") for c in corners]
                # fan-triangulate polygons
                for k in range(1, len(idx) - 1):
                    tri = (idx[0], idx[k], idx[k + 1])
                    f_v.append([int(c[0]) for c in tri])
                    f_t.append([int(c[1]) if len(c) > 1 and c[1] else 0 for c in tri])
        vertices = np.asarray(v, dtype=np.float64)
        faces = np.asarray(f_v, dtype=np.int64) - 1
    except ValueError as e:
        raise AssetError(f"{obj_path}: malformed OBJ ({e})") from None
    if vertices.ndim != 2 or len(vertices) < 3 or len(faces) == 0:
        raise AssetError(f"{obj_path}: mesh has no triangles")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise AssetError(f"{obj_path}: face index out of range")
    face_uvs = texture = None
    if vt and with_texture:
        uv = np.asarray(vt, dtype=np.float64)
        ft = np.asarray(f_t, dtype=np.int64) - 1
        if ft.min() >= 0 and ft.max() < len(uv):
            face_uvs = uv[ft]
        tex_path = obj_path.parent / "texture_map.png"
        if tex_path.is_file():
            from PIL import Image

            try:
                with Image.open(tex_path) as im:
                    texture = np.asarray(im.convert("RGB")).copy()
            except Exception as e:
                raise AssetError(f"{tex_path}: unreadable texture ({e})") from None
    return MeshData(vertices, faces, face_uvs, texture)


@dataclass(frozen=True)
class PhysicalProperties:
    """Derived physical properties of an object, in its mesh frame (metres, kg).

    Attributes:
        box_center: (3,) centre of the axis-aligned bounding box (collision box pose).
        box_size: (3,) edge lengths of the bounding box (the collision geometry).
        mass: kg.
        com: (3,) centre of mass.
        inertia: (3, 3) rotational inertia about the centre of mass, kg m^2.
        from_volume: True if computed from the closed mesh volume, False if the bounding-box fallback
            (uniform solid box) was used because the mesh is not a valid closed surface.
    """

    box_center: np.ndarray
    box_size: np.ndarray
    mass: float
    com: np.ndarray
    inertia: np.ndarray
    from_volume: bool


def physical_properties(mesh: MeshData, mass: float) -> PhysicalProperties:
    """Bounding box, centre of mass and inertia of a mesh of uniform density and total ``mass``.

    Uses the divergence theorem over signed tetrahedra (origin, triangle) for volume, first and
    second moments. Falls back to a uniform solid bounding box if the signed volume is not positive or
    the result is not a valid inertia (open or badly oriented meshes).
    """
    V = mesh.vertices
    lo, hi = V.min(0), V.max(0)
    center, size = (lo + hi) / 2, hi - lo
    a, b, c = (V[mesh.faces[:, k]] for k in range(3))
    det = np.einsum("ij,ij->i", a, np.cross(b, c))  # 6 * signed tet volume
    vol = det.sum() / 6.0
    ok = vol > 1e-3 * float(np.prod(np.maximum(size, 1e-6)))
    if ok:
        com = (det[:, None] * (a + b + c)).sum(0) / (24.0 * vol)
        # second moments: integral of x_i x_j over each tet = det/120 * (sum_k v_k,i v_k,j + s_i s_j)
        s = a + b + c
        C = (np.einsum("n,ni,nj->ij", det, a, a) + np.einsum("n,ni,nj->ij", det, b, b)
             + np.einsum("n,ni,nj->ij", det, c, c) + np.einsum("n,ni,nj->ij", det, s, s)) / 120.0
        rho = mass / vol
        C = rho * C - mass * np.outer(com, com)  # covariance about the centre of mass
        inertia = np.trace(C) * np.eye(3) - C
        ev = np.linalg.eigvalsh(inertia)
        ok = bool(
            ev.min() > 0
            and ev[0] + ev[1] >= ev[2] * (1 - 1e-6)
            and np.all(com >= lo - 1e-9)
            and np.all(com <= hi + 1e-9)
        )
    if not ok:
        com = center
        inertia = mass / 12.0 * np.diag(
            [size[1] ** 2 + size[2] ** 2, size[0] ** 2 + size[2] ** 2, size[0] ** 2 + size[1] ** 2]
        )
    return PhysicalProperties(center, size, float(mass), np.asarray(com), np.asarray(inertia), bool(ok))


def sample_surface(mesh: MeshData, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sample ``n`` points uniformly by area on the mesh surface, with face normals and texture colours.

    Returns:
        points (n, 3) metres, normals (n, 3) unit, colors (n, 3) float in [0, 1] (grey if untextured).
    """
    rng = np.random.default_rng(seed)
    V, F = mesh.vertices, mesh.faces
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cr = np.cross(b - a, c - a)
    area = np.linalg.norm(cr, axis=1)
    keep = area > 0
    face = rng.choice(np.flatnonzero(keep), size=n, p=area[keep] / area[keep].sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    w = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)  # barycentric weights
    pts = w[:, :1] * a[face] + w[:, 1:2] * b[face] + w[:, 2:] * c[face]
    nrm = cr[face] / area[face, None]
    if mesh.face_uvs is not None and mesh.texture is not None:
        uv = np.einsum("nk,nkd->nd", w, mesh.face_uvs[face])
        h, wd = mesh.texture.shape[:2]
        px = np.clip(np.round((uv[:, 0] % 1.0) * (wd - 1)).astype(int), 0, wd - 1)
        py = np.clip(np.round((1 - uv[:, 1] % 1.0) * (h - 1)).astype(int), 0, h - 1)
        col = mesh.texture[py, px].astype(np.float64) / 255.0
    else:
        col = np.full((n, 3), 0.5)
    return pts, nrm, col


def point_cloud_diameter(points: np.ndarray) -> float:
    """Largest distance between two of ``points`` (N, 3), exact, via the convex hull."""
    from scipy.spatial import ConvexHull

    pts = np.asarray(points, dtype=np.float64)
    try:
        hull = pts[ConvexHull(pts).vertices]
    except Exception:  # degenerate (flat) sets
        hull = pts
    best = 0.0
    for i in range(0, len(hull), 512):
        d = np.linalg.norm(hull[i : i + 512, None, :] - hull[None, :, :], axis=-1)
        best = max(best, float(d.max()))
    return best
