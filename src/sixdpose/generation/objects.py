"""The objects of a dataset: which are targets (with obj_ids and merged-mask codes) and which are noise,
resolved once from the config and the asset directories (:func:`resolve_objects`).

Targets come from the YCB asset directory (``target_source="ycb"``: the paper's 18 by default) or from
a BOP dataset's ``models/`` (``target_source="bop"``: converted once to OBJ in metres by
:func:`sixdpose.assets.bop.converted_model`, so the ground truth is in the BOP model frames, with the
BOP obj_ids). Noise objects are YCB objects. The resolved :class:`ObjectSet` is plain data: the main
process makes it (converting BOP models) and hands it to every scene worker.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from ..assets import AssetError, load_catalog, load_mesh
from ..assets.bop import BOP_YCB_MAPS, converted_model, list_bop_models, model_mass
from ..constants import TARGET_OBJECTS, merged_mask_codes
from ..errors import ConfigError
from .config import GenerationConfig


@dataclass(frozen=True)
class SceneObject:
    """One object the generator can drop.

    Attributes:
        name: its name in the dataset (``obj_name``, mask folder, model file): the YCB name, or
            ``obj_NNNNNN`` for a BOP model.
        obj_path: the textured OBJ mesh in metres that Drake renders and the physics and reference
            model are computed from (a YCB ``textured.obj`` or a converted BOP model).
        mass: kg. symmetric: evaluated with ADD-S (targets).
        role: ``"target"`` or ``"noise"``. obj_id: object id of a target (None for noise).
        ycb_name: the YCB object it is (None for a BOP model without a YCB name).
        source: ``"ycb"`` or the BOP PLY file name. sha256: content hash of the BOP source (None for YCB).
    """

    name: str
    obj_path: Path
    mass: float
    symmetric: bool
    role: str
    obj_id: int | None = None
    ycb_name: str | None = None
    source: str = "ycb"
    sha256: str | None = None


@dataclass(frozen=True)
class ObjectSet:
    """Targets (in obj_id order) and noise pool of a dataset, with the merged-mask codes.

    Attributes:
        targets: target objects in obj_id order. noise: noise objects (catalogue order).
        codes: target name -> merged-mask code (:func:`sixdpose.constants.merged_mask_codes`).
    """

    targets: tuple[SceneObject, ...]
    noise: tuple[SceneObject, ...]
    codes: dict = field(default_factory=dict)

    @property
    def catalogue(self) -> dict[str, SceneObject]:
        """Every object by name (targets, then noise)."""
        return {o.name: o for o in self.targets + self.noise}

    @property
    def target_names(self) -> list[str]:
        """Target names in obj_id order."""
        return [o.name for o in self.targets]

    @property
    def noise_names(self) -> list[str]:
        """Noise pool names."""
        return [o.name for o in self.noise]

    @property
    def obj_ids(self) -> dict[str, int]:
        """Target name -> obj_id."""
        return {o.name: int(o.obj_id) for o in self.targets}


def _check_subset(kind: str, names, allowed, where: str) -> None:
    bad = [n for n in names if n not in allowed]
    if bad:
        raise AssetError(f"{where}: unknown {kind} object(s) {', '.join(bad)}")


def _ycb_targets(cfg: GenerationConfig, catalog, csv: Path) -> list[SceneObject]:
    if cfg.target_objects is None:
        missing = [n for n in TARGET_OBJECTS if n not in catalog]
        if missing:
            raise AssetError(f"{csv.parent}: target object(s) missing from the asset directory: {', '.join(missing)}")
        names = list(TARGET_OBJECTS)
    else:
        names = list(cfg.target_objects)
        _check_subset("target", names, catalog, f"{csv} (--targets)")
        if set(names) == set(TARGET_OBJECTS):  # the paper's set keeps the paper's ids and codes
            names = list(TARGET_OBJECTS)
    sym = set(cfg.symmetric_objects) if cfg.symmetric_objects is not None else None
    if sym is not None:
        _check_subset("symmetric", cfg.symmetric_objects, catalog, f"{csv} (symmetric_objects)")
    return [SceneObject(n, catalog[n].obj_path, catalog[n].mass,
                        (n in sym) if sym is not None else catalog[n].symmetric,
                        "target", k + 1, n) for k, n in enumerate(names)]


def _bop_ids(tokens, models: dict, ycb_map: dict[int, str], where: str, kind: str) -> list[int]:
    by_ycb = {v: k for k, v in ycb_map.items()}
    out = []
    for tok in tokens:
        t = str(tok).strip()
        oid = None
        if t.isdigit():
            oid = int(t)
        elif t.startswith("obj_") and t[4:].isdigit():
            oid = int(t[4:])
        elif t in by_ycb:
            oid = by_ycb[t]
        if oid is None or oid not in models:
            known = "obj_NNNNNN, an obj_id" + (" or a YCB name of the map" if ycb_map else "")
            raise AssetError(f"{where}: unknown {kind} object {t!r} (not a model of this directory; give {known})")
        out.append(oid)
    return out


def _bop_targets(cfg: GenerationConfig, bop_dir: Path, catalog, cache_dir) -> list[SceneObject]:
    models = list_bop_models(bop_dir)
    ycb_map = BOP_YCB_MAPS.get(cfg.bop_ycb_map or "", {})
    ids = (sorted(models) if cfg.target_objects is None
           else sorted(_bop_ids(cfg.target_objects, models, ycb_map, str(bop_dir), "target")))
    sym_ids = None
    if cfg.symmetric_objects is not None:
        sym_ids = set(_bop_ids(cfg.symmetric_objects, models, ycb_map, str(bop_dir), "symmetric"))
    out = []
    for oid in ids:
        m = models[oid]
        obj, digest = converted_model(m.ply_path, cache_dir)
        ycb = ycb_map.get(oid)
        mass = model_mass(load_mesh(obj, with_texture=False), catalog[ycb].mass if ycb in catalog else None)
        out.append(SceneObject(m.name, obj, mass, (oid in sym_ids) if sym_ids is not None else m.symmetric,
                               "target", oid, ycb, m.ply_path.name, digest))
    return out


def resolve_objects(cfg: GenerationConfig, assets_dir: str | os.PathLike, bop_models: str | os.PathLike | None = None,
                    cache_dir: str | os.PathLike | None = None) -> ObjectSet:
    """Resolve the targets and the noise pool of ``cfg`` (converting BOP models on first use).

    Args:
        cfg: the generator config (``target_source``, ``target_objects``, ``noise_objects``,
            ``symmetric_objects``, ``bop_ycb_map``, ``max_instances``).
        assets_dir: YCB asset directory (noise objects, YCB targets, masses of mapped BOP objects).
        bop_models: a BOP ``models/`` directory (needed when ``cfg.target_source == "bop"``).
        cache_dir: where converted BOP models are kept (default
            :func:`sixdpose.assets.bop.default_cache_dir`).
    Returns:
        the :class:`ObjectSet`.
    Raises:
        AssetError: a missing directory or model, a PLY without faces, an unknown name in
            ``target_objects`` / ``noise_objects`` / ``symmetric_objects``, an object both target and
            noise. ConfigError: too many targets for the merged-mask codes.
    """
    assets_dir = Path(assets_dir)
    catalog = load_catalog(assets_dir)
    csv = assets_dir / "objects.csv"
    if cfg.target_source == "bop":
        if bop_models is None:
            raise AssetError("target_source is bop but no BOP models directory was given (--assets-bop DIR/models)")
        targets = _bop_targets(cfg, Path(bop_models), catalog, cache_dir)
    else:
        targets = _ycb_targets(cfg, catalog, csv)
    taken = {t.ycb_name: t.name for t in targets if t.ycb_name}
    if cfg.noise_objects is None:
        noise_names = [n for n in catalog if n not in taken]
    else:
        noise_names = list(cfg.noise_objects)
        _check_subset("noise", noise_names, catalog, f"{csv} (--noise)")
        both = [f"{n} (target {taken[n]})" if taken[n] != n else n for n in noise_names if n in taken]
        if both:
            raise AssetError(f"object(s) both target and noise: {', '.join(both)}")
    noise = [SceneObject(n, catalog[n].obj_path, catalog[n].mass, catalog[n].symmetric, "noise", None, n)
             for n in noise_names]
    try:
        codes = merged_mask_codes([t.name for t in targets], cfg.max_instances)
    except ValueError as e:
        raise ConfigError(f"target_objects: {e}") from None
    return ObjectSet(tuple(targets), tuple(noise), codes)
