"""How much the colour-verification step depends on the camera's colours: RANSAC + ICP on the
validation split (every 5th image, GT masks, >= 400 px, one thread) with the RGB as rendered, with it
perturbed per image (per-channel gain 0.75-1.25, gamma 0.8-1.25, Gaussian noise sigma 6/255, a rough
stand-in for another camera's white balance and response), and without the colour step.

Usage::

    python benchmarks/colour_robustness.py [--data data/val] [--stride 5] [--method ransac]
        [--results-dir results] [--result-name colour_robustness] [--no-result]

The three rows are also written as the result artifact ``results/colour_robustness.json``.
"""

from __future__ import annotations

import os

for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_k] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from sixdpose.constants import MIN_VISIBLE_PX  # noqa: E402


class PerturbedColours:
    """A :class:`~sixdpose.datasets.base.DatasetReader` whose samples' RGB is perturbed, reproducibly
    per image (random per-channel gain, gamma and noise); everything else is the wrapped reader's."""

    def __init__(self, ds):
        self._ds = ds
        self._index = {k: i for i, k in enumerate(ds.keys())}
        self.location, self.has_depth, self.has_masks, self.manifest = (
            ds.location,
            ds.has_depth,
            ds.has_masks,
            ds.manifest,
        )

    def __len__(self):
        return len(self._ds)

    def __getitem__(self, i):
        return self.load(self._ds.keys()[i])

    def keys(self):
        return self._ds.keys()

    @property
    def object_ids(self):
        return self._ds.object_ids

    def model(self, obj_id):
        return self._ds.model(obj_id)

    def load(self, key, *, masks=True, rgb=True, depth=True):
        s = self._ds.load(key, masks=masks, rgb=rgb, depth=depth)
        if s.rgb is not None:
            rng = np.random.default_rng(1000 + self._index[tuple(key)])
            x = s.rgb.astype(np.float64) / 255.0
            x = np.clip(x * rng.uniform(0.75, 1.25, 3), 0, 1) ** rng.uniform(0.8, 1.25)
            x = np.clip(x + rng.normal(0, 6 / 255, x.shape), 0, 1)
            s.rgb = (x * 255).astype(np.uint8)
        return s


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="dataset (default: data/val, generated with the val profile)")
    ap.add_argument("--stride", type=int, default=5)
    ap.add_argument("--method", default="ransac", choices=["ransac", "fgr", "super4pcs"])
    from sixdpose.artifacts.results import add_result_arguments, save_from_args, script_command

    add_result_arguments(ap, "colour_robustness", Path(__file__).resolve().parents[1] / "results")
    args = ap.parse_args(argv)

    from sixdpose.datasets import DatasetReader, open_dataset
    from sixdpose.evaluation.evaluate import evaluate
    from sixdpose.registration.presets import get_preset
    from sixdpose.registration.runner import run_registration

    data = args.data
    if data is None:
        from sixdpose.generation import ensure_dataset

        data = ensure_dataset(Path(__file__).resolve().parents[1] / "data" / "val", profile="val")
    ds = open_dataset(data)
    perturbed = PerturbedColours(ds)
    assert isinstance(perturbed, DatasetReader)
    idx = range(0, len(ds), args.stride)
    table = []
    for label, reader, colour in (
        ("rendered RGB", ds, True),
        ("perturbed RGB", perturbed, True),
        ("no colour step", ds, False),
    ):
        rows = run_registration(reader, args.method, icp=True, cfg=get_preset("default", colour_verify=colour),
                                workers=1, min_px=MIN_VISIBLE_PX, progress=False, indices=idx)
        res = evaluate(ds, rows, min_px=MIN_VISIBLE_PX)
        print(f"{args.method}+icp  {label:16s} ADD(-S) {res.accuracy:6.2f}% ({res.n_correct}/{res.n_gt})", flush=True)
        table.append({"condition": label, "method": args.method + "+icp", "colour_step": colour,
                      "add_s_accuracy": res.accuracy, "n_correct": res.n_correct, "n_gt": res.n_gt})
    save_from_args(args, table, command=script_command(__file__, argv),
                   units={"add_s_accuracy": "%", "n_correct": "GT instances", "n_gt": "GT instances"},
                   description=f"{args.method} + ICP (default preset, GT masks, >= {MIN_VISIBLE_PX} px, one thread) "
                               f"on every "
                               f"{args.stride}-th image of {Path(str(data)).name}: rendered RGB, perturbed RGB "
                               f"(gain 0.75-1.25, gamma 0.8-1.25, noise 6/255), no colour step",
                   config={"data": str(data), "stride": args.stride, "method": args.method, "min_px": MIN_VISIBLE_PX,
                           "preset": get_preset("default").to_dict()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
