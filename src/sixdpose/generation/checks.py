"""Self-checks of a generated dataset (used by the tests, handy for users' own datasets)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..assets import load_catalog, load_mesh, resolve_assets_dir
from ..datasets.geometry import backproject
from ..geometry import X_from


def _mesh_source(root: Path, assets, bop_models):
    """name -> mesh loader for a dataset's objects: YCB meshes by name, and for targets whose
    ``models_info.yml`` ``source`` is a BOP PLY the original PLY in ``bop_models`` (mm -> m)."""
    from ..assets import MeshData
    from ..datasets.ply import read_ply
    from ..datasets.synthetic import load_yaml

    catalog = load_catalog(resolve_assets_dir(assets))
    info = load_yaml(root / "models" / "models_info.yml") or {}

    def mesh(name: str) -> MeshData:
        src = str((info.get(name) or {}).get("source", "ycb"))
        if src.endswith(".ply"):
            if bop_models is None:
                raise ValueError(f"{name} is a BOP model ({src}): pass bop_models")
            ply = read_ply(Path(bop_models) / src)
            return MeshData(ply.vertices / 1000.0, ply.faces, None, None)
        return load_mesh(catalog[name].obj_path, with_texture=False)

    return mesh


def gt_surface_errors(dataset_dir: str | Path, assets: str | Path | None = None, max_images: int | None = None,
                      bop_models: str | Path | None = None) -> list[dict]:
    """For every annotated instance: mean and median distance (metres) between its back-projected
    masked depth, moved into the object frame with the inverse GT pose, and the mesh surface.

    The mesh is the YCB mesh of the object, or for BOP targets the original BOP PLY in ``bop_models``
    (converted from mm to m), so the check is against the BOP model frame itself.

    Returns:
        list of ``{"im_id", "obj_name", "obj_id", "inst", "n", "mean", "median"}``.
    """
    import open3d as o3d

    from ..datasets.synthetic import SyntheticDataset

    ds = SyntheticDataset(dataset_dir)
    mesh_of = _mesh_source(Path(dataset_dir), assets, bop_models)
    scenes: dict[str, o3d.t.geometry.RaycastingScene] = {}
    out = []
    for key in ds.keys()[: max_images or None]:
        s = ds.load(key)
        for inst in s.instances:
            if inst.obj_name not in scenes:
                m = mesh_of(inst.obj_name)
                rs = o3d.t.geometry.RaycastingScene()
                rs.add_triangles(
                    o3d.core.Tensor(m.vertices.astype(np.float32)), o3d.core.Tensor(m.faces.astype(np.uint32))
                )
                scenes[inst.obj_name] = rs
            p_C = backproject(s.depth, s.K, inst.mask)[0]
            if len(p_C) == 0:
                continue
            p_O = (p_C - inst.t) @ inst.R  # R^T (p - t)
            d = scenes[inst.obj_name].compute_distance(o3d.core.Tensor(p_O.astype(np.float32))).numpy()
            out.append(
                {
                    "im_id": s.im_id,
                    "obj_name": inst.obj_name,
                    "obj_id": inst.obj_id,
                    "inst": inst.inst,
                    "n": len(d),
                    "mean": float(d.mean()),
                    "median": float(np.median(d)),
                }
            )
    return out


def box_penetration(X_a: np.ndarray, size_a: np.ndarray, X_b: np.ndarray, size_b: np.ndarray) -> float:
    """Penetration depth (metres, 0 if apart) of two oriented boxes, by the separating axis theorem.

    Args:
        X_a, X_b: (4, 4) poses of the box centres in a common frame; size_a, size_b: (3,) edge lengths.
    Returns:
        the smallest overlap over the 15 candidate axes (0.0 if some axis separates them).
    """
    Ra, Rb = X_a[:3, :3], X_b[:3, :3]
    d = X_b[:3, 3] - X_a[:3, 3]
    ha, hb = np.asarray(size_a) / 2, np.asarray(size_b) / 2
    axes = [Ra[:, i] for i in range(3)] + [Rb[:, i] for i in range(3)]
    axes += [np.cross(Ra[:, i], Rb[:, j]) for i in range(3) for j in range(3)]
    best = np.inf
    for ax in axes:
        n = np.linalg.norm(ax)
        if n < 1e-9:
            continue
        ax = ax / n
        ra = np.sum(ha * np.abs(Ra.T @ ax))
        rb = np.sum(hb * np.abs(Rb.T @ ax))
        overlap = ra + rb - abs(d @ ax)
        if overlap <= 0:
            return 0.0
        best = min(best, overlap)
    return float(best)


def resting_penetrations(
    dataset_dir: str | Path, assets: str | Path | None = None, bop_models: str | Path | None = None
) -> dict:
    """Worst penetrations after settling, from the final poses in ``manifest.json`` (``bop_models``:
    the BOP models directory of a dataset with BOP targets).

    Returns:
        ``{"table": metres the lowest contact point of an object on the table lies below the table
        top, "pairs": largest box-box penetration between two objects, "pair": (name, name)}``.
    """
    from ..assets import physical_properties
    from ..datasets.base import DatasetError
    from ..datasets.synthetic import load_manifest
    from .config import GenerationConfig

    root = Path(dataset_dir)
    man = load_manifest(root / "manifest.json")
    if not man:
        raise DatasetError(f"{root}: no manifest.json (not a generated dataset)")
    cfg = GenerationConfig.from_dict(man["config"])
    mesh_of = _mesh_source(root, assets, bop_models)
    worst_table, worst_pair, pair = 0.0, 0.0, None
    hx, hy = cfg.table_size[0] / 2, cfg.table_size[1] / 2
    for scene in man["scenes"].values():
        boxes = []
        for o in scene["objects"]:
            if o["left_scene"]:
                continue
            pr = physical_properties(mesh_of(o["name"]), 1.0)  # the box only: the mass does not matter
            R_WO, t_WO = np.asarray(o["R_WO"], dtype=float), np.asarray(o["t_WO"], dtype=float)
            Xc = X_from(R_WO, R_WO @ pr.box_center + t_WO)  # the object's box in the world
            corners = (
                Xc[:3, :3]
                @ (np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)]) * pr.box_size / 2).T
            ).T + Xc[:3, 3]
            over_table = (np.abs(corners[:, 0]) < hx) & (np.abs(corners[:, 1]) < hy)
            on_table = Xc[2, 3] > cfg.table_height and abs(Xc[0, 3]) < hx and abs(Xc[1, 3]) < hy
            if on_table and over_table.any():
                worst_table = max(worst_table, float(cfg.table_height - corners[over_table, 2].min()))
            boxes.append((o["name"], Xc, pr.box_size))
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                p = box_penetration(boxes[i][1], boxes[i][2], boxes[j][1], boxes[j][2])
                if p > worst_pair:
                    worst_pair, pair = p, (boxes[i][0], boxes[j][0])
    return {"table": worst_table, "pairs": worst_pair, "pair": pair}


#: Width of the boundary band of :func:`depth_hole_stats`, pixels.
EDGE_BAND_PX = 3


def mask_hole_counts(depth: np.ndarray, mask: np.ndarray, edge_px: int = EDGE_BAND_PX) -> dict:
    """Holes of one depth map inside one object mask, split into a boundary band and the interior.

    Args:
        depth: (H, W) float depth in metres; a hole is 0, NaN, inf or negative.
        mask: (H, W) bool visible mask of the object.
        edge_px: width of the band: mask pixels within ``edge_px`` px (chessboard distance) of a
            pixel outside the mask or of the image border are ``edge``, the others ``interior``.
    Returns:
        ``{"px", "holes", "edge_px", "edge_holes", "interior_px", "interior_holes"}`` (int counts).
    Raises:
        ValueError: shapes differ, or edge_px < 0.
    """
    from scipy import ndimage

    depth, mask = np.asarray(depth), np.asarray(mask, dtype=bool)
    if depth.shape != mask.shape or depth.ndim != 2:
        raise ValueError(f"depth {depth.shape} and mask {mask.shape} must be the same (H, W)")
    if edge_px < 0:
        raise ValueError(f"edge_px must be >= 0, got {edge_px}")
    with np.errstate(invalid="ignore"):
        hole = ~(np.isfinite(depth) & (depth > 0))
    if edge_px > 0:
        interior = ndimage.binary_erosion(mask, np.ones((3, 3), bool), iterations=edge_px, border_value=0)
    else:
        interior = mask
    edge = mask & ~interior
    return {"px": int(mask.sum()), "holes": int((hole & mask).sum()),
            "edge_px": int(edge.sum()), "edge_holes": int((hole & edge).sum()),
            "interior_px": int(interior.sum()), "interior_holes": int((hole & interior).sum())}


def depth_hole_stats(data, *, split: str = "train_real", scenes=None, max_images: int | None = None,
                     edge_px: int = EDGE_BAND_PX, depth_fn=None, residual: bool = False) -> dict:
    """Depth statistics over the visible-object masks of a dataset: how much of each object a depth
    sensor (real or simulated) fails to measure, at the object's rim and inside it.

    Args:
        data: a dataset path or reader (:func:`sixdpose.datasets.readers.as_reader`) with GT
            visible masks and depth.
        split: the BOP split of a path (``train_real``: the YCB-Video sample's); ignored otherwise.
        scenes: scene ids to use (None: all).
        max_images: at most this many images (in key order, after the scene filter).
        edge_px: width of the rim band in pixels (:func:`mask_hole_counts`).
        depth_fn: optional ``f(sample) -> (H, W) depth`` replacing the dataset's depth (e.g. a sensor
            model applied to an ideal dataset's depth); None uses ``sample.depth``.
        residual: also the distance (metres) of every measured masked pixel, back-projected and moved
            into the object frame by the GT pose, to the nearest model point (``reader.model``'s
            points; a KD-tree, so bounded below by the points' spacing).
    Returns:
        ``{"images", "instances", "px", "hole", "edge_hole", "interior_hole", "edge_share"}``: pooled
        pixel fractions (holes / masked pixels; ``edge_share`` = edge pixels / masked pixels), plus
        ``"residual_median"`` and ``"residual_p90"`` (metres) when ``residual``.
    Raises:
        DatasetError: the dataset has no depth or no masks.
    """
    from ..datasets.base import DatasetError
    from ..datasets.geometry import backproject
    from ..datasets.readers import as_reader

    reader = as_reader(data, split=split)
    if not reader.has_masks or (depth_fn is None and not reader.has_depth):
        raise DatasetError(f"{reader.location}: hole statistics need visible masks and depth")
    wanted = None if scenes is None else {int(x) for x in scenes}
    keys = [k for k in list(reader.keys()) if wanted is None or k[0] in wanted][: max_images or None]
    tot = dict.fromkeys(("px", "holes", "edge_px", "edge_holes", "interior_px", "interior_holes"), 0)
    n_inst, dists, trees = 0, [], {}
    for key in keys:
        s = reader.load(key, rgb=depth_fn is not None)
        depth = s.depth if depth_fn is None else depth_fn(s)
        if depth is None:
            raise DatasetError(f"{reader.location}: image {key} has no depth")
        for inst in s.instances:
            if inst.mask is None or not inst.mask.any():
                continue
            c = mask_hole_counts(depth, inst.mask, edge_px)
            for k in tot:
                tot[k] += c[k]
            n_inst += 1
            if residual:
                from scipy.spatial import cKDTree

                if inst.obj_id not in trees:
                    trees[inst.obj_id] = cKDTree(reader.model(inst.obj_id).points)
                p_C = backproject(np.asarray(depth, dtype=np.float32), s.K, inst.mask)[0]
                if len(p_C):
                    dists.append(trees[inst.obj_id].query((p_C - inst.t) @ inst.R)[0])

    def frac(a, b):
        return float(tot[a] / tot[b]) if tot[b] else float("nan")

    out = {"images": len(keys), "instances": n_inst, "px": tot["px"], "hole": frac("holes", "px"),
           "edge_hole": frac("edge_holes", "edge_px"), "interior_hole": frac("interior_holes", "interior_px"),
           "edge_share": frac("edge_px", "px")}
    if residual:
        d = np.concatenate(dists) if dists else np.zeros(0)
        out["residual_median"] = float(np.median(d)) if d.size else float("nan")
        out["residual_p90"] = float(np.percentile(d, 90)) if d.size else float("nan")
    return out
