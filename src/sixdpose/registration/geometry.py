"""Point-cloud geometry for the hybrid methods (paper section IV-B).

* :func:`backproject`: masked depth image -> camera-frame points (metres) with colours, vectorised.
* :func:`estimate_normals`: plane fit on the k=10 nearest neighbours, oriented toward the camera
  (negative z component for points in front of the camera), as in the paper.
* :func:`model_reference`: a voxel-downsampled reference cloud of an object (2 mm in the paper) with
  normals and FPFH features, cached per (object, voxel size) in a :class:`ReferenceCache`.

All arrays are float64, metres; poses are 4x4 homogeneous ``X_CO`` (object in camera).
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field

import numpy as np

from ..datasets.geometry import backproject  # noqa: F401  (re-exported: part of this stage's API)

#: The camera centre in the camera frame (default viewpoint of :func:`estimate_normals`).
_ORIGIN = np.zeros(3)


def to_o3d(points: np.ndarray, normals: np.ndarray | None = None, colors: np.ndarray | None = None):
    """Wrap (N, 3) arrays into an ``open3d.geometry.PointCloud``."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(points, dtype=np.float64)))
    if normals is not None:
        pcd.normals = o3d.utility.Vector3dVector(np.ascontiguousarray(normals, dtype=np.float64))
    if colors is not None:
        pcd.colors = o3d.utility.Vector3dVector(np.ascontiguousarray(colors, dtype=np.float64))
    return pcd


def estimate_normals(pcd, knn: int = 10, camera: np.ndarray | None = _ORIGIN):
    """Estimate normals in place by a plane fit on the ``knn`` nearest neighbours.

    Args:
        pcd: ``open3d.geometry.PointCloud`` (camera frame, metres).
        knn: neighbours of the plane fit (paper: 10).
        camera: (3,) camera centre to orient normals toward (default: origin, i.e. normals get a
            negative z for points in front of the camera); ``None`` keeps Open3D's orientation.
    Returns:
        ``pcd`` (same object).
    """
    import open3d as o3d

    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=knn))
    if camera is not None and len(pcd.points):
        pcd.orient_normals_towards_camera_location(np.asarray(camera, dtype=np.float64))
    return pcd


def compute_fpfh(pcd, radius: float, max_nn: int = 100):
    """FPFH features (33, N) of a point cloud that has normals (Open3D)."""
    import open3d as o3d

    return o3d.pipelines.registration.compute_fpfh_feature(
        pcd, o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=max_nn)
    )


def sample_mesh_surface(vertices: np.ndarray, triangles: np.ndarray, spacing: float, seed: int = 0):
    """Sample points with normals uniformly on a triangle mesh, about one per ``spacing``^2 of area.

    Args:
        vertices: (V, 3) metres. triangles: (F, 3) int. spacing: target point spacing, metres.
    Returns:
        points (N, 3), normals (N, 3) (face normals, outward if the mesh is consistently oriented).
    """
    v0, v1, v2 = (vertices[triangles[:, i]] for i in range(3))
    cross = np.cross(v1 - v0, v2 - v0)
    area2 = np.linalg.norm(cross, axis=1)
    total = 0.5 * area2.sum()
    n = int(min(max(total / (spacing * spacing) * 2.0, 500), 400_000))
    rng = np.random.default_rng(seed)
    p = area2 / area2.sum() if area2.sum() > 0 else None
    f = rng.choice(len(triangles), size=n, p=p)
    r1, r2 = rng.random(n), rng.random(n)
    s1 = np.sqrt(r1)
    a, b, c = 1 - s1, s1 * (1 - r2), s1 * r2
    pts = a[:, None] * v0[f] + b[:, None] * v1[f] + c[:, None] * v2[f]
    nrm = cross[f] / np.maximum(area2[f], 1e-20)[:, None]
    return pts, nrm


@dataclass
class Reference:
    """A preprocessed reference model for one object at one voxel size.

    Attributes:
        obj_id: object id. voxel: voxel size (m). diameter: model diameter (m). symmetric: ADD-S flag.
        points, normals: (M, 3) downsampled model cloud (object frame, metres) with outward normals.
        pcd: the same as an Open3D cloud. fpfh: its FPFH features (``Feature``, 33 x M) or None.
        prep_time: seconds spent building it (charged once to the first instance that needs it).
    """

    obj_id: int
    voxel: float
    diameter: float
    symmetric: bool
    points: np.ndarray
    normals: np.ndarray
    pcd: object
    fpfh: object | None
    prep_time: float = 0.0
    extra: dict = field(default_factory=dict)


def model_reference(model, voxel: float, fpfh_radius: float | None = None, mesh=None, knn: int = 10) -> Reference:
    """Build the reference cloud of ``model``: voxel-downsampled points with outward normals and FPFH.

    Args:
        model: :class:`~sixdpose.datasets.base.ObjectModel` (metres).
        voxel: voxel size in metres (paper: 0.002).
        fpfh_radius: FPFH search radius in metres (None: no features).
        mesh: optional ``(vertices, triangles)``: the surface is then sampled uniformly first (BOP
            meshes have few vertices on flat faces).
        knn: neighbours for normals if the model has none.
    Returns:
        A :class:`Reference`.
    """
    t0 = time.perf_counter()
    if mesh is not None:
        pts, nrm = sample_mesh_surface(mesh[0], mesh[1], spacing=voxel / 2.0)
        # orient face normals outward (meshes may be inconsistently wound): away from the centroid
        flip = np.einsum("ij,ij->i", pts - pts.mean(axis=0), nrm) < 0
        if model.normals is None:
            nrm[flip] *= -1
        else:  # keep the mesh's own orientation, but fix per-face sign by the nearest vertex normal
            from scipy.spatial import cKDTree

            _, idx = cKDTree(model.points).query(pts, k=1)
            nrm[np.einsum("ij,ij->i", nrm, model.normals[idx]) < 0] *= -1
    else:
        pts, nrm = model.points, model.normals
    pcd = to_o3d(pts, nrm)
    pcd = pcd.voxel_down_sample(voxel) if voxel > 0 else pcd
    if not pcd.has_normals():
        import open3d as o3d

        pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=knn))
        c = np.asarray(pcd.points).mean(axis=0)
        n = np.asarray(pcd.normals)
        n[np.einsum("ij,ij->i", np.asarray(pcd.points) - c, n) < 0] *= -1
        pcd.normals = __import__("open3d").utility.Vector3dVector(n)
    else:
        pcd.normalize_normals()
    feat = compute_fpfh(pcd, fpfh_radius) if fpfh_radius else None
    return Reference(
        obj_id=int(model.obj_id),
        voxel=float(voxel),
        diameter=float(model.diameter),
        symmetric=bool(model.symmetric),
        points=np.asarray(pcd.points).copy(),
        normals=np.asarray(pcd.normals).copy(),
        pcd=pcd,
        fpfh=feat,
        prep_time=time.perf_counter() - t0,
    )


class ReferenceCache:
    """Per-process cache of the model-side data of registration: :class:`Reference` clouds keyed by
    (obj_id, voxel, fpfh_radius) and colour grids keyed by (obj_id, cells, smoothing).

    Building an object's model-side data on its first use (reading the model file, sampling, normals,
    FPFH, colour grid, verification surface) is the object's *onboarding*: a one-time cost per object and
    process, as BOP 2023 times an object's onboarding apart from the per-image run time. Its seconds add up
    in :attr:`onboarding_s`; ``register`` and ``predict-pose`` leave them out of the per-image times and
    record the total in the results CSV's ``.config.yml`` (``onboarding_s``).

    Args:
        dataset: a :class:`~sixdpose.datasets.base.DatasetReader` (its ``model(obj_id)``).
    """

    def __init__(self, dataset):
        self.dataset = dataset
        self._refs: dict[tuple, Reference] = {}
        self._grids: dict[tuple, object] = {}
        #: other per-object data of the stage (verification surfaces), keyed by the module that builds it
        self.extra: dict[tuple, object] = {}
        #: seconds spent building model-side data so far (see the class docstring)
        self.onboarding_s = 0.0
        self._depth = 0

    @contextlib.contextmanager
    def onboarding(self):
        """Context manager around the first-use build of an object's model-side data: its wall time is
        added to :attr:`onboarding_s` (nested builds count once, in the outermost)."""
        self._depth += 1
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self._depth -= 1
            if self._depth == 0:
                self.onboarding_s += time.perf_counter() - t0

    def colour_grid(self, obj_id: int, cells: int, smooth_rel: float):
        """The :class:`~sixdpose.registration.verify.ColourGrid` of ``obj_id`` (None if the model has no
        colours); returns ``(grid, seconds spent building it now)`` (0.0 when it was cached)."""
        key = (int(obj_id), int(cells), float(smooth_rel))
        if key in self._grids:
            return self._grids[key], 0.0
        from .verify import build_grid

        with self.onboarding():
            model = self.dataset.model(obj_id)
            grid = None if model.colors is None else build_grid(model.points, model.colors, model.diameter,
                                                                  cells=cells, smooth_rel=smooth_rel)
        self._grids[key] = grid
        return grid, (0.0 if grid is None else grid.time)

    def get(self, obj_id: int, voxel: float, fpfh_radius: float | None) -> tuple[Reference, float]:
        """Return ``(reference, seconds spent building it now)`` (0.0 when it was cached)."""
        key = (int(obj_id), round(float(voxel), 6), None if fpfh_radius is None else round(float(fpfh_radius), 6))
        if key in self._refs:
            return self._refs[key], 0.0
        with self.onboarding():
            model = self.dataset.model(obj_id)
            ref = model_reference(model, voxel, fpfh_radius, mesh=model.mesh)
        self._refs[key] = ref
        return ref, ref.prep_time
