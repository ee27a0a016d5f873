"""Does the verification score the true pose above its near-symmetric turns? A check of the scoring alone.

For every GT instance (>= 400 visible pixels) of the chosen objects of a synthetic split, the GT pose and
its turns by the model's near-symmetries (``hypotheses.near_symmetries``, the hypotheses that
``--set verify_near_symmetries=6`` adds) are scored against the frame by ``hypotheses.score_hypotheses``
with the settings of ``benchmarks/verify_test.py`` (near-symmetries, grey detail). Prints, per object, in how
many instances the true pose scores above every turn, the median lead over the best turn and how many lead
by at least ``verify_min_gain`` (what a turned input pose needs to be replaced). No registration runs: a
miss here is the scoring's, not the search's.

    python benchmarks/truth_vs_turns.py [--data data/val] [--objs 1,5,16] [--set KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from sixdpose.config import parse_overrides
from sixdpose.datasets.readers import open_dataset
from sixdpose.geometry import X_from
from sixdpose.registration.geometry import ReferenceCache
from sixdpose.registration.hypotheses import Frame, model_surface, near_symmetries, score_hypotheses
from sixdpose.registration.presets import PRESETS, VAL_CHOSEN_VERIFY


def main() -> None:
    """Score every instance's true pose against its turns and print the counts per object."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default="data/val")
    ap.add_argument("--objs", default="", help="comma-separated obj ids (default: every object)")
    ap.add_argument("--min-px", type=int, default=400)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a registration config field")
    a = ap.parse_args()
    ds = open_dataset(a.data)
    over = {**VAL_CHOSEN_VERIFY, **parse_overrides(a.set)}
    cfg = dataclasses.replace(PRESETS["default"], **over)
    cache = ReferenceCache(ds)
    objs = [int(o) for o in a.objs.split(",")] if a.objs else sorted(ds.object_ids)
    surf = {o: model_surface(cache, o, cfg)[0] for o in objs}
    turns = {o: near_symmetries(surf[o], keep=cfg.verify_near_symmetries) for o in objs}
    leads: dict[int, list[float]] = {o: [] for o in objs if len(turns[o])}
    keys = ds.keys()  # (a reader iterates over samples, not keys)
    for key in keys:
        s = ds.load(key)
        for inst in s.instances:
            o = inst.obj_id
            if o not in leads or inst.mask is None or s.depth is None or inst.mask.sum() < a.min_px:
                continue
            X = X_from(inst.R, inst.t)
            sc = score_hypotheses(np.concatenate([X[None], X[None] @ turns[o]]), surf[o],
                                  Frame(s.depth, s.K, inst.mask, s.rgb), cfg).score
            leads[o].append(float(sc[0] - sc[1:].max()))
    print(f"{a.data}: the true pose against its near-symmetric turns (verify_min_gain {cfg.verify_min_gain})")
    tot = [0, 0]
    for o, g in leads.items():
        if not g:
            continue
        g_ = np.asarray(g)
        tot[0] += int((g_ > 0).sum())
        tot[1] += len(g_)
        print(f"{o:3d} {ds.object_ids[o]:28s} turns {len(turns[o])}  truth above every turn {(g_ > 0).sum()} of "
              f"{len(g_)}  median lead {np.median(g_):+.3f}  lead >= min_gain {(g_ >= cfg.verify_min_gain).sum()}")
    print(f"all: truth above every turn in {tot[0]} of {tot[1]} instances")


if __name__ == "__main__":
    main()
