"""Running the generator: validation, models, parallel scenes (local processes or Ray), resume.

The unit of work is a scene, seeded from ``(seed, scene index)``; image numbers are
``scene * views + view``. Output therefore does not depend on the number of workers or their order.
"""

from __future__ import annotations

import dataclasses
import os
import resource
import shutil
import sys
import time
import traceback
from pathlib import Path

import numpy as np

from .. import __version__
from ..assets import load_mesh, physical_properties, point_cloud_diameter, resolve_assets_dir, sample_surface
from ..assets.bop import resolve_bop_models_dir
from ..datasets.layout import model_file, write_models_info
from ..datasets.ply import write_ply
from ..errors import SixdposeError
from ..fileio import atomic_write_text, claim_output_dir, write_if_changed
from .config import GenerationConfig
from .config import profile as get_profile
from .objects import ObjectSet, resolve_objects
from .scene import camera_arc, sample_scene, scene_rng
from .sensors import sensor_rng, simulate_depth
from .writer import PARTIAL, RECORDS, commit_scene, finalize, read_records, scene_files, write_attribution

CONFIG_FILE = "config.yml"
GENERATOR = f"sixdpose.generation {__version__}"


class GenerationError(SixdposeError):
    """Bad arguments or output directory; the message is one line naming the problem."""


# ----------------------------------------------------------------------------------------------
# one scene (runs in a worker process)
# ----------------------------------------------------------------------------------------------
_PROPS: dict = {}


def _props(catalog, name):
    obj = catalog[name]
    key = (name, str(obj.obj_path), float(obj.mass))
    if key not in _PROPS:
        _PROPS[key] = physical_properties(load_mesh(obj.obj_path, with_texture=False), obj.mass)
    return _PROPS[key]


def _flat(a) -> list:
    return [float(x) for x in np.asarray(a, dtype=np.float64).ravel()]


def _rows(a) -> list:
    return [[float(x) for x in row] for row in np.asarray(a, dtype=np.float64)]


def render_scene(root: Path, cfg: GenerationConfig, objects: ObjectSet | Path, scene: int) -> dict:
    """Simulate, render and commit scene ``scene`` into dataset ``root``.

    Args:
        root: dataset directory. cfg: its config. objects: the resolved :class:`~.objects.ObjectSet`
            (or, for YCB targets, the YCB asset directory to resolve it from). scene: scene index.
    Returns:
        ``{"scene", "ok", "images", "seconds", "peak_rss_mb"}`` plus ``"error"`` if the scene failed
        (it then has no record and is retried by the next run).
    """
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        from .sim import SceneSimulator, intrinsics, set_catalogue

        objset = objects if isinstance(objects, ObjectSet) else resolve_objects(cfg, objects)
        catalog = objset.catalogue
        targets, noise, obj_ids = objset.target_names, objset.noise_names, objset.obj_ids
        set_catalogue(catalog)
        K = intrinsics(cfg)
        for attempt in range(cfg.max_attempts):
            rng = scene_rng(cfg.seed, scene, attempt)
            specs = sample_scene(rng, cfg, _PropsView(catalog), targets, noise)
            cams = camera_arc(rng, cfg)
            sim = SceneSimulator(specs, _PropsView(catalog), {s.name: catalog[s.name].obj_path for s in specs}, cfg)
            res = sim.settle()
            if res.at_rest:
                break
        else:
            raise RuntimeError(
                f"not at rest after {cfg.sim_time} s (or the simulation diverged) in {cfg.max_attempts} attempts"
            )
        views, images = {}, []
        look = None
        if cfg.randomise > 0:  # domain randomisation: colours per scene, camera and light per view
            from .randomise import randomise_view, scene_look, view_look

            look = scene_look(cfg.seed, scene, [k + 1 for k, s in enumerate(specs)
                                                if s.role == "noise" and k not in res.left], cfg.randomise)
        for v, X_WC in enumerate(cams):
            im_id = scene * cfg.views + v
            rgb, depth, label = sim.render(X_WC)
            if look is not None:
                rgb = randomise_view(rgb, label, look, view_look(cfg.seed, scene, v, cfg.randomise))
            if cfg.sensor != "ideal":  # what the sensor sees; masks and poses stay exact
                depth = simulate_depth(depth, K, cfg.sensor, sensor_rng(cfg.seed, scene, v), rgb=rgb)
            X_CW = np.linalg.inv(X_WC)
            insts, objs = [], []
            for k, s in enumerate(specs):
                if s.role != "target" or k in res.left:
                    continue
                mask = label == k + 1
                px = int(mask.sum())
                if px == 0:
                    continue
                X_CO = X_CW @ res.X_WO[k]
                insts.append((s.name, s.inst, mask))
                objs.append({"obj_name": s.name, "obj_id": obj_ids[s.name], "inst": s.inst,
                             "R": _rows(X_CO[:3, :3]), "t": _flat(X_CO[:3, 3]), "px_visib": px})
            views[im_id] = {"rgb": rgb, "depth": depth, "instances": insts}
            images.append({"im_id": im_id, "cam_K": _rows(K), "cam_R_WC": _rows(X_WC[:3, :3]),
                           "cam_t_WC": _flat(X_WC[:3, 3]), "objects": objs})
        objects = [
            {"name": s.name, "role": s.role, "inst": s.inst, "dropped_off_table": s.off_table,
             "off_table": k in res.off_table, "left_scene": k in res.left,
             "R_WO": _rows(res.X_WO[k][:3, :3]), "t_WO": _flat(res.X_WO[k][:3, 3])}
            for k, s in enumerate(specs)
        ]
        record = {"scene": scene, "attempt": attempt, "sim_time": round(res.sim_time, 6),
                  "image_range": [scene * cfg.views, scene * cfg.views + cfg.views - 1],
                  "objects": objects, "images": images}
        commit_scene(root, scene, scene_files(views, objset.codes), record)
        return {"scene": scene, "ok": True, "images": cfg.views, "seconds": time.perf_counter() - t0,
                "cpu_seconds": time.process_time() - c0, "attempts": attempt + 1,
                "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}
    except Exception as e:  # recorded per scene; the run goes on
        return {"scene": scene, "ok": False, "images": 0, "seconds": time.perf_counter() - t0,
                "cpu_seconds": time.process_time() - c0,
                "error": f"{type(e).__name__}: {e}", "traceback": traceback.format_exc(),
                "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


class _PropsView(dict):
    """Lazy name -> PhysicalProperties mapping backed by the per-process cache."""

    def __init__(self, catalog):
        super().__init__()
        self._catalog = catalog

    def __missing__(self, name):
        return _props(self._catalog, name)


#: scenes a generation worker renders before the pool replaces it (bounds the renderer's memory)
_TASKS_PER_WORKER = 50


def _worker_init():
    # after workers.init_worker (process_pool): die with the parent; Ctrl-C is the parent's
    # llvmpipe: one rendering thread per worker (workers are the parallelism)
    os.environ.setdefault("LP_NUM_THREADS", "1")


def _worker(args):
    root, cfg_dict, objects, scene = args
    return render_scene(Path(root), GenerationConfig.from_dict(cfg_dict), objects, scene)


# ----------------------------------------------------------------------------------------------
# models, validation, driver
# ----------------------------------------------------------------------------------------------
def _source_entry(t) -> dict:
    return {"source": t.source, **({"source_sha256": t.sha256} if t.sha256 else {})}


def write_models(root: Path, cfg: GenerationConfig, objects: ObjectSet) -> None:
    """Write ``models/<target>.ply`` (coloured, with normals, metres, in the target's model frame: the
    YCB mesh frame or the BOP model frame) and ``models/models_info.yml`` (per target: ``obj_id``,
    ``diameter`` and bounding box in metres, ``symmetric``, ``mask_code``, ``source``, and for BOP
    models ``source_sha256``)."""
    info = {}
    for t in objects.targets:
        mesh = load_mesh(t.obj_path)
        pts, nrm, col = sample_surface(mesh, cfg.model_points, seed=t.obj_id)
        write_ply(root / model_file(t.name), pts, nrm, col, comment="sixdpose reference model, metres")
        lo, hi = mesh.vertices.min(0), mesh.vertices.max(0)
        info[t.name] = {
            "obj_id": int(t.obj_id),
            "diameter": float(point_cloud_diameter(mesh.vertices)),
            "min_x": float(lo[0]), "min_y": float(lo[1]), "min_z": float(lo[2]),
            "size_x": float(hi[0] - lo[0]), "size_y": float(hi[1] - lo[1]), "size_z": float(hi[2] - lo[2]),
            "symmetric": bool(t.symmetric),
            "mask_code": int(objects.codes[t.name]),
            **_source_entry(t),
        }
    write_models_info(root, info)


def check_models(root: Path, objects: ObjectSet) -> None:
    """Raise :class:`GenerationError` if the dataset's ``models/models_info.yml`` was written for other
    targets than ``objects`` (other names or obj_ids, or BOP models with other content)."""
    from ..datasets.synthetic import load_yaml

    path = root / "models" / "models_info.yml"
    try:
        info = load_yaml(path) or {}
        have = {str(k): (int(v["obj_id"]), v.get("source_sha256")) for k, v in info.items()}
    except (SixdposeError, KeyError, TypeError, ValueError, AttributeError) as e:
        raise GenerationError(f"{path}: unreadable ({e})") from None
    want = {t.name: (int(t.obj_id), t.sha256) for t in objects.targets}
    diff = sorted(n for n in set(have) | set(want) if n not in have or n not in want or have[n][0] != want[n][0]
                  or (have[n][1] is not None and have[n][1] != want[n][1]))
    if diff:
        raise GenerationError(
            f"{path}: the dataset was made with other target models ({', '.join(diff[:5])}); use another --out"
        )


def prepare_output(out: Path, cfg: GenerationConfig) -> bool:
    """Check ``out`` can hold this dataset. Returns True if it resumes an existing one.

    A non-empty directory is accepted only if it is a dataset of this generator (it has
    ``config.yml``; :func:`sixdpose.fileio.claim_output_dir`) made with the same configuration
    (``scenes`` may grow: the run then extends it).

    Raises:
        OutputError: ``out`` is a file, unwritable or foreign. GenerationError: made with another
            configuration.
    """
    resume = claim_output_dir(out, "generate", marker=CONFIG_FILE, write_marker=False)
    if resume:
        cfg_file = out / CONFIG_FILE
        try:
            old = GenerationConfig.load(cfg_file)
        except SixdposeError as e:
            raise GenerationError(f"unreadable dataset config ({e})") from None
        if old.replace(scenes=cfg.scenes) != cfg:
            diff = [
                f.name
                for f in dataclasses.fields(cfg)
                if getattr(old, f.name) != getattr(cfg, f.name) and f.name != "scenes"
            ]
            raise GenerationError(
                f"{out}: holds a dataset made with a different config ({', '.join(diff)}); use another --out"
            )
    return resume


def generate(
    out: str | os.PathLike,
    cfg: GenerationConfig,
    workers: int = 1,
    assets: str | os.PathLike | None = None,
    executor: str = "local",
    address: str | None = None,
    progress: bool = True,
    assets_bop: str | os.PathLike | None = None,
    cache_dir: str | os.PathLike | None = None,
) -> dict:
    """Generate (or finish, or extend) a dataset in ``out``.

    Args:
        out: output directory (created; an existing dataset with the same config is resumed).
        cfg: configuration (see :mod:`.config`).
        workers: parallel scene workers (local processes; with Ray, CPUs requested when starting a
            local instance).
        assets: YCB asset directory (default: ``$SIXDPOSE_YCB``).
        executor: ``"local"`` or ``"ray"``.
        address: Ray cluster address (``None``: start a local instance).
        progress: show a progress bar on stderr.
        assets_bop: BOP ``models/`` directory of the targets when ``cfg.target_source == "bop"``
            (default: :func:`sixdpose.assets.bop.resolve_bop_models_dir`).
        cache_dir: cache of converted BOP models (default :func:`sixdpose.assets.bop.default_cache_dir`).
    Returns:
        summary dict: ``scenes_done``, ``scenes_failed`` (list of {scene, error}), ``images``,
        ``seconds`` (wall), ``images_per_s``, ``cpu_seconds`` (summed over the scene workers),
        ``peak_rss_mb`` (largest worker), ``manifest``, ``bop_export`` (path or None).
    Raises:
        GenerationError, AssetError, ConfigError: bad arguments (nothing is written then).
    """
    if workers < 1:
        raise GenerationError(f"--workers must be >= 1, got {workers}")
    if executor not in ("local", "ray"):
        raise GenerationError(f"--executor must be 'local' or 'ray', got {executor!r}")
    if assets_bop is not None and cfg.target_source != "bop":
        raise GenerationError("--assets-bop needs target_source=bop (set by the CLI's --assets-bop)")
    assets_dir = resolve_assets_dir(assets)
    bop_dir = resolve_bop_models_dir(assets_bop, cfg.bop_ycb_map) if cfg.target_source == "bop" else None
    objects = resolve_objects(cfg, assets_dir, bop_dir, cache_dir)
    out = Path(out)
    resuming = prepare_output(out, cfg)
    if resuming and (out / "models" / "models_info.yml").is_file():
        check_models(out, objects)

    out.mkdir(parents=True, exist_ok=True)
    write_if_changed(out / CONFIG_FILE, cfg.to_yaml())
    shutil.rmtree(out / PARTIAL, ignore_errors=True)
    (out / RECORDS).mkdir(exist_ok=True)
    if not (out / "models" / "models_info.yml").is_file():
        write_models(out, cfg, objects)
    write_attribution(out, assets_dir)

    records = read_records(out)
    todo = [s for s in range(cfg.scenes) if s not in records]
    t0 = time.perf_counter()
    results = []
    from tqdm import tqdm

    bar = tqdm(total=cfg.scenes, initial=cfg.scenes - len(todo), unit="scene", desc="generate",
               disable=not progress, file=sys.stderr, dynamic_ncols=True)
    images = 0
    for r in _run(todo, out, cfg, objects, workers, executor, address):
        results.append(r)
        images += r["images"]
        bar.update(1)
        el = time.perf_counter() - t0
        bar.set_postfix_str(
            f"{images / el:.2f} img/s" + (f", {sum(not x['ok'] for x in results)} failed" if not r["ok"] else "")
        )
        if not r["ok"]:
            bar.write(f"scene {r['scene']} failed: {r['error']}")
    bar.close()
    seconds = time.perf_counter() - t0
    failed = [{"scene": r["scene"], "error": r["error"]} for r in results if not r["ok"]]
    import pydrake

    head = {
        "generator": GENERATOR,
        "drake": getattr(pydrake, "__version__", None) or _drake_version(),
        "seed": cfg.seed,
        "config": cfg.to_dict(),
        "attribution": "ATTRIBUTION.txt",
        "failed_scenes": sorted(f["scene"] for f in failed),
    }
    records = read_records(out)
    manifest = finalize(out, records, head)
    exported = None
    if cfg.bop_export and not failed and len(records) >= cfg.scenes:
        exported = export_copy(out, cfg.bop_export, manifest["num_images"], progress)
    return {
        "resumed": resuming,
        "scenes_done": sum(r["ok"] for r in results),
        "scenes_failed": failed,
        "images": images,
        "seconds": seconds,
        "images_per_s": images / seconds if seconds > 0 else float("nan"),
        "cpu_seconds": sum(r["cpu_seconds"] for r in results),
        "peak_rss_mb": max((r["peak_rss_mb"] for r in results), default=0.0),
        "manifest": manifest,
        "bop_export": None if exported is None else str(exported),
    }


BOP_COPY = "bop"


def export_copy(root: Path, split: str, num_images: int, progress: bool = False) -> Path:
    """Write the BOP copy of a finished dataset to ``root/bop`` (split ``split``), as
    :func:`sixdpose.datasets.bop.export_bop` does, unless an up-to-date copy is there (same split and
    number of images); an outdated or interrupted copy is removed first. Returns ``root/bop``."""
    import json

    from ..datasets.bop import export_bop
    from ..datasets.synthetic import SyntheticDataset

    dst = root / BOP_COPY
    stamp = dst / "sixdpose_export.json"
    want = {"split": split, "num_images": int(num_images)}
    try:
        if json.loads(stamp.read_text()) == want:
            return dst
    except (OSError, ValueError):
        pass
    shutil.rmtree(dst, ignore_errors=True)
    export_bop(SyntheticDataset(root), dst, split=split, progress=progress)
    atomic_write_text(stamp, json.dumps(want) + "\n")
    return dst


def _drake_version() -> str | None:
    try:
        from importlib.metadata import version

        return version("drake")
    except Exception:
        return None


def _run(todo, out, cfg, objects, workers, executor, address):
    args = [(str(out), cfg.to_dict(), objects, s) for s in todo]
    if not args:
        return
    if executor == "ray":
        yield from _run_ray(args, workers, address)
        return
    from ..workers import process_pool

    # leaving the block by an exception (KeyboardInterrupt, the consumer closing this generator) ends the
    # workers; finishing closes the pool and waits for them
    with process_pool(min(workers, len(args)), _worker_init, maxtasksperchild=_TASKS_PER_WORKER) as pool:
        yield from pool.imap_unordered(_worker, args)


def _run_ray(args, workers, address):
    import ray

    started = False
    if not ray.is_initialized():
        kw = {"address": address} if address else {"num_cpus": workers, "include_dashboard": False}
        ray.init(ignore_reinit_error=True, log_to_driver=False, **kw)
        started = True
    try:
        task = ray.remote(num_cpus=1, runtime_env={"env_vars": {"LP_NUM_THREADS": "1"}})(_worker)
        pending = [task.remote(a) for a in args]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            yield ray.get(done[0])
    finally:
        if started:
            ray.shutdown()


def ensure_dataset(path: str | os.PathLike, profile: str = "smoke", workers: int | None = None, **overrides) -> Path:
    """Return ``path``, generating the named profile's dataset there first if it is not complete.

    Used by the notebooks so each can run on its own (``profile``: smoke, demo or paper;
    ``overrides``: config fields such as ``scenes``).
    """
    path = Path(path)
    cfg = get_profile(profile, **overrides)
    if (
        (path / "gt.yml").is_file()
        and (path / CONFIG_FILE).is_file()
        and GenerationConfig.load(path / CONFIG_FILE) == cfg
        and len(read_records(path)) >= cfg.scenes
    ):
        return path
    generate(path, cfg, workers=workers or min(2, os.cpu_count() or 1))
    return path
