"""Tune / measure hypothesis verification on the YCB-Video sample without re-running the global method.

Pass 1 runs the hybrid chain once per instance (``register``'s code path, verification stubbed to record
its inputs); pass 2 runs :func:`sixdpose.registration.hypotheses.verify_hypotheses` with each variant
(``--variant name:field=value,field=value``) and prints ADD(-S) per scene and object and the seconds per
instance of the verification alone.

    python benchmarks/tune_verify.py --method super4pcs --scene 0 --variant base: --variant t2:verify_turns=2
"""

from __future__ import annotations

import argparse
import dataclasses
import time

from sixdpose.datasets.readers import open_dataset
from sixdpose.evaluation.metrics import add_or_adds
from sixdpose.registration import hypotheses as H
from sixdpose.registration import methods as M
from sixdpose.registration.geometry import ReferenceCache, backproject
from sixdpose.registration.presets import get_preset
from sixdpose.registration.runner import instance_seed


def main() -> None:
    """Parse the arguments, run both passes, print the table."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default="../shared/data/ycbv_sample")
    ap.add_argument("--split", default="train_real")
    ap.add_argument("--method", default="super4pcs")
    ap.add_argument("--scene", type=int, action="append")
    ap.add_argument("--symmetric-ids", default="1,13,14,16,18,19,20,21")
    ap.add_argument("--variant", action="append", default=[])
    a = ap.parse_args()
    sym = {int(x) for x in a.symmetric_ids.split(",")}
    ds = open_dataset(a.data, split=a.split)
    cache = ReferenceCache(ds)
    cfg0 = get_preset("default", verify=True)
    rec: list = []

    def record(X_CO, surface, frame, cfg, extra=None, icp=None, obj_id=None):
        rec.append((X_CO, extra, icp, frame))
        return H.Verified(X_CO, 0.0, 0, 1, 0, False)

    real = M.__dict__.get("verify_hypotheses")
    H_verify = H.verify_hypotheses
    H.verify_hypotheses = record
    items = []
    t_chain = 0.0
    for i, key in enumerate(ds.keys()):
        if a.scene and key[0] not in a.scene:
            continue
        s = ds[i]
        for k, ins in enumerate(s.instances):
            cfg = dataclasses.replace(cfg0, seed=instance_seed(0, s.scene_id, s.im_id, ins.obj_id, k))
            pts, col, _ = backproject(s.depth, s.K, ins.mask, s.rgb)
            fr = H.Frame(s.depth, s.K, ins.mask, s.rgb)
            t0 = time.perf_counter()
            M.estimate_pose(pts, ins.obj_id, a.method, cache, cfg, icp=True, colors=col, frame=fr)
            t_chain += time.perf_counter() - t0
            m = ds.model(ins.obj_id)
            items.append((s.scene_id, ins.obj_id, ins.R, ins.t, m, rec[-1]))
    H.verify_hypotheses = H_verify
    del real
    print(f"chain without verification: {len(items)} instances, {t_chain / len(items) * 1000:.0f} ms/instance")

    def correct(X, R, t, m):
        e = add_or_adds(X[:3, :3], X[:3, 3], R, t, m.points, m.obj_id in sym)
        return e < 0.1 * m.diameter

    variants = [("none", None)] + [(v.split(":")[0], v.split(":", 1)[1]) for v in a.variant]
    for name, spec in variants:
        res: dict = {}
        tv = 0.0
        for sc, oid, R, t, m, (X_CO, extra, icp, fr) in items:
            if spec is None:
                X = X_CO
            else:
                ov = {}
                for kv in filter(None, spec.split(",")):
                    f, val = kv.split("=")
                    typ = type(getattr(cfg0, f))
                    ov[f] = (val.lower() in ("1", "true")) if typ is bool else (
                        typ(float(val)) if typ is int else typ(val))
                cfg = dataclasses.replace(cfg0, **ov)
                surf, _ = H.model_surface(cache, oid, cfg)
                t0 = time.perf_counter()
                X = H.verify_hypotheses(X_CO, surf, fr, cfg, extra=extra, icp=icp, obj_id=oid).X_CO
                tv += time.perf_counter() - t0
            res.setdefault((sc, oid), []).append(correct(X, R, t, m))
        tot = sum(sum(v) for v in res.values())
        n = sum(len(v) for v in res.values())
        per = " ".join(f"s{sc}/o{oid}:{sum(v)}/{len(v)}" for (sc, oid), v in sorted(res.items()))
        print(f"{name:12s} {100 * tot / n:6.2f}% ({tot}/{n})  verify {tv / n * 1000:5.0f} ms/inst  {per}", flush=True)


if __name__ == "__main__":
    main()
