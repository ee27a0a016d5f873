"""The paper's Fig. 2: LINEMOD-Occlusion frames beside frames of our generated data, annotated so the
paper's point (section III: LM-O is one scene seen from one side at about one distance with an upright
camera and no repeated object; the generated data varies all of these) can be read off each frame.

Each frame carries a caption computed from its ground truth (nothing typed):

* ``d``: the median camera-to-object distance in metres (the norms of the instances' ``t`` of ``X_CO``);
* ``view``: the optical axis' angle below the table plane, in degrees;
* ``roll``: the angle between the image's "up" and the table's up projected into the image, in degrees;
* ``az.``: the camera's side, its azimuth around the table in degrees: in the generator's world frame (about
  the table's centre) for ours; for LM-O, about the upright reference object (the object seen in most
  frames: the scene is static, so any fixed object gives the same sides up to an offset);
* the instances, the distinct objects and the objects that repeat (``2x 006_mustard_bottle``).

The table's up direction in the camera frame comes from the generator's camera pose (``cam_R_WC`` of
``gt.yml``) where the dataset has one (ours); else from the objects' own +z axes where most of them agree
(LM-O: its models stand upright on one table, their +z axes within a few degrees of each other), else
from a plane fitted through the annotated objects' centres (oriented towards the camera). Above each
row, the same quantities summarised over every frame of that dataset (at most :data:`MAX_SUMMARY`
frames, evenly spaced).

Command line (writes the PNG; the make graph's notebook 02 calls :func:`draw_fig2` too)::

    python -m sixdpose.reporting.fig2 --lmo ../shared/data/lmo --ours data/demo \
        --out figures/demo/fig2_lmo_vs_ours.png
"""

from __future__ import annotations

import argparse
import math
import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..datasets.base import DatasetReader, Sample
from ..errors import SixdposeError
from ..fileio import atomic_write_bytes

#: Frames whose annotations enter a row's summary line (evenly spaced over the dataset).
MAX_SUMMARY = 500
#: Figure size per column (inches) and resolution: a figure of ``n`` columns is ``n * 400 x 760`` pixels.
COLUMN_INCHES = 4.0
HEIGHT_INCHES = 7.6
DPI = 100


@dataclass(frozen=True)
class FrameView:
    """How one frame sees its objects (from its ground truth).

    Attributes:
        distance: median camera-to-object distance (m). view_deg: optical axis below the table plane (deg;
        None: fewer than 3 objects and no camera pose). roll_deg: image up against the table's up (deg; None
        as view_deg, or the view steeper than :data:`ROLL_MAX_VIEW_DEG`). n_instances, n_objects: annotated
        instances and distinct objects. azimuth_deg: the camera's side (deg; None without a camera pose or
        an upright reference object). repeated: object name -> number of instances, for the objects seen
        more than once. up_from: ``camera`` (the generator's camera pose), ``object axes`` or ``plane fit``
        (the objects' centres).
    """

    distance: float
    view_deg: float | None
    roll_deg: float | None
    azimuth_deg: float | None
    n_instances: int
    n_objects: int
    repeated: dict[str, int]
    up_from: str


def up_from_centres(t: np.ndarray) -> np.ndarray | None:
    """The table's up direction in the camera frame, (3,) unit vector, from the (N, 3) object centres
    ``t`` (metres, camera frame): the normal of their least-squares plane, oriented towards the camera.
    None for fewer than 3 centres."""
    t = np.asarray(t, dtype=float).reshape(-1, 3)
    if len(t) < 3:
        return None
    c = t.mean(axis=0)
    n = np.linalg.svd(t - c)[2][-1]
    return -n if float(n @ -c) < 0 else n


#: Views steeper than this (degrees below the table plane) have no meaningful roll: looking straight down, the
#: table's up projects to (almost) a point in the image, so their roll is left out (``roll_deg`` None).
ROLL_MAX_VIEW_DEG = 75.0
#: Cosine above which an object's +z axis counts as agreeing with the others' mean (about 26 degrees).
AXIS_AGREEMENT = 0.9


def up_from_axes(R: np.ndarray) -> np.ndarray | None:
    """The table's up direction in the camera frame, (3,) unit vector, as the mean +z axis of the (N, 3, 3)
    object rotations ``R`` (``X_CO``) that agree with it (cosine above :data:`AXIS_AGREEMENT`); None when
    fewer than half of at least 2 objects agree (objects lying in any orientation, as in our data)."""
    z = np.asarray(R, dtype=float).reshape(-1, 3, 3)[:, :, 2]
    if len(z) < 2:
        return None
    m = z.mean(axis=0)
    if np.linalg.norm(m) == 0:
        return None
    keep = z[z @ (m / np.linalg.norm(m)) > AXIS_AGREEMENT]
    if 2 * len(keep) < len(z):
        return None
    m = keep.mean(axis=0)
    return m / np.linalg.norm(m)


def angles(up_C: np.ndarray) -> tuple[float, float]:
    """``(view_deg, roll_deg)`` of a camera whose table-up direction in its frame (+x right, +y down, +z
    forward) is ``up_C`` (3,): the optical axis' angle below the table plane and the angle of the
    projected up against the image's up (the conventions of
    :func:`sixdpose.datasets.stats.dataset_statistics`)."""
    up = np.asarray(up_C, dtype=float) / np.linalg.norm(up_C)
    view = math.degrees(math.asin(float(np.clip(-up[2], -1.0, 1.0))))
    roll = math.degrees(math.atan2(up[0], -up[1]))
    return view, roll


def frame_view(sample: Sample, camera: tuple[np.ndarray, np.ndarray] | None = None,
               ref_obj: int | None = None) -> FrameView:
    """The :class:`FrameView` of ``sample``. ``camera``: ``(cam_R_WC (3, 3), cam_t_WC (3,) m)``, the camera's
    pose in a world frame whose +z is up and whose table is centred on the z axis, where the dataset
    records it; else the up direction from :func:`up_from_axes` (then the azimuth about the instance of
    ``ref_obj`` when the frame shows it), else from :func:`up_from_centres` (no azimuth)."""
    t = np.array([i.t for i in sample.instances], dtype=float).reshape(-1, 3)
    names = Counter(i.obj_name for i in sample.instances)
    azimuth = None
    if camera is not None:
        up, src = np.asarray(camera[0], dtype=float).T @ np.array([0.0, 0.0, 1.0]), "camera"
        azimuth = math.degrees(math.atan2(float(camera[1][1]), float(camera[1][0])))
    elif (up := up_from_axes(np.array([i.R for i in sample.instances]))) is not None:
        src = "object axes"
        ref = next((i for i in sample.instances if i.obj_id == ref_obj), None)
        if ref is not None:
            p_O = -np.asarray(ref.R, dtype=float).T @ np.asarray(ref.t, dtype=float)  # the camera in the object frame
            azimuth = math.degrees(math.atan2(p_O[1], p_O[0]))
    else:
        up, src = up_from_centres(t), "plane fit"
    view, roll = angles(up) if up is not None else (None, None)
    if view is not None and view > ROLL_MAX_VIEW_DEG:
        roll = None
    return FrameView(distance=float(np.median(np.linalg.norm(t, axis=1))) if len(t) else math.nan,
                     view_deg=view, roll_deg=roll, azimuth_deg=azimuth, n_instances=len(sample.instances),
                     n_objects=len(names),
                     repeated={k: v for k, v in sorted(names.items()) if v > 1}, up_from=src)


def _camera(ds: DatasetReader, sample: Sample) -> tuple[np.ndarray, np.ndarray] | None:
    from ..datasets.synthetic import SyntheticDataset

    # the synthetic reader's gt.yml entries hold the generator's camera pose (BOP has no world frame)
    entry = ds.gt.get(sample.im_id) if isinstance(ds, SyntheticDataset) else None
    if not isinstance(entry, dict) or "cam_R_WC" not in entry or "cam_t_WC" not in entry:
        return None
    return np.asarray(entry["cam_R_WC"], dtype=float), np.asarray(entry["cam_t_WC"], dtype=float)


def reference_object(ds: DatasetReader) -> int | None:
    """The obj_id seen in most of (at most :data:`MAX_SUMMARY`) frames of ``ds`` (the azimuth's reference
    where there is no camera pose); None without annotations."""
    seen: Counter = Counter()
    for k in pick_frames(ds, MAX_SUMMARY):
        seen.update({i.obj_id for i in ds.load(k, masks=False, rgb=False, depth=False).instances})
    return seen.most_common(1)[0][0] if seen else None


def azimuth_span(azimuths: list[float]) -> float:
    """The smallest arc (degrees, 0-360) holding every azimuth of ``azimuths`` (degrees): 360 minus the
    largest gap between neighbours on the circle; 0 for fewer than 2."""
    a = sorted(x % 360.0 for x in azimuths)
    if len(a) < 2:
        return 0.0
    gaps = [b - c for c, b in zip(a, a[1:], strict=False)] + [a[0] + 360.0 - a[-1]]
    return 360.0 - max(gaps)


def caption(v: FrameView) -> str:
    """Two caption lines for a frame: distance, view and roll; instances, objects and repeats."""
    roll = "roll n/a (top-down)" if v.roll_deg is None else f"roll {v.roll_deg:+.0f}°"
    ang = "view/roll n/a" if v.view_deg is None else f"view {v.view_deg:.0f}°, {roll}"
    if v.azimuth_deg is not None:
        ang += f", az. {v.azimuth_deg:+.0f}°"
    rep = ", ".join(f"{n}x {k}" for k, n in v.repeated.items()) or "no repeated object"
    if len(rep) > 48:
        rep = rep[:45] + "..."
    return f"d {v.distance:.2f} m, {ang}\n{v.n_instances} inst. / {v.n_objects} obj.; {rep}"


def summary(ds: DatasetReader, name: str, ref_obj: int | None = None) -> str:
    """One line over (at most :data:`MAX_SUMMARY`) frames of ``ds``: ranges of distance, view and roll (of
    the frames that have one), the arc of camera sides (:func:`azimuth_span`; about ``ref_obj`` where there
    is no camera pose), and the fraction of frames with a repeated object."""
    views = []
    for k in pick_frames(ds, MAX_SUMMARY):
        s = ds.load(k, masks=False, rgb=False, depth=False)
        if s.instances:
            views.append(frame_view(s, _camera(ds, s), ref_obj))
    if not views:
        return f"{name}: no annotated frame"

    def rng(vals, fmt):
        vals = [x for x in vals if x is not None and math.isfinite(x)]
        return "n/a" if not vals else f"{fmt.format(min(vals))} to {fmt.format(max(vals))}"

    rep = sum(bool(v.repeated) for v in views) / len(views)
    return (f"{name}, {len(views)} frames: d {rng([v.distance for v in views], '{:.2f}')} m, view "
            f"{rng([v.view_deg for v in views], '{:.0f}')}°, roll {rng([v.roll_deg for v in views], '{:+.0f}')}°, "
            f"sides over {azimuth_span([v.azimuth_deg for v in views if v.azimuth_deg is not None]):.0f}°, "
            f"{100 * rep:.0f} % of frames with a repeated object (up from: "
            f"{', '.join(sorted({v.up_from for v in views}))})")


def pick_frames(ds: DatasetReader, n: int) -> list:
    """``n`` keys of ``ds`` evenly spaced over its frames (all of them when it has fewer)."""
    keys = ds.keys()
    if len(keys) <= n:
        return list(keys)
    return [keys[i] for i in np.linspace(0, len(keys) - 1, n).astype(int)]


def draw_fig2(lmo: DatasetReader | None, ours: DatasetReader, n: int = 3, lmo_name: str = "LM-O",
              ours_name: str = "ours (generated)"):
    """Fig. 2: ``n`` frames of ``lmo`` (top row) above ``n`` frames of ``ours`` (bottom row), each with
    its :func:`caption`, each row headed by its :func:`summary`. ``lmo`` None: the top row says the
    LM-O frames are not here.

    Returns:
        the matplotlib ``Figure`` (``n * COLUMN_INCHES`` x ``HEIGHT_INCHES`` inches).
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, n, figsize=(COLUMN_INCHES * n, HEIGHT_INCHES), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for row, (ds, name) in enumerate(((lmo, lmo_name), (ours, ours_name))):
        if ds is None:
            axes[row][0].text(0.0, 0.5, f"{name}: dataset not given", fontsize=9, va="center")
            continue
        ref = reference_object(ds)
        for ax, key in zip(axes[row], pick_frames(ds, n), strict=False):  # fewer frames than columns: blanks
            s = ds.load(key, masks=False, depth=False)
            ax.imshow(s.rgb)
            ax.set_title(f"{name} {s.scene_id}/{s.im_id}\n" + caption(frame_view(s, _camera(ds, s), ref)),
                         fontsize=7.5)
        axes[row][0].annotate(summary(ds, name, ref), xy=(0.0, 1.0), xycoords="axes fraction", xytext=(0, 42),
                              textcoords="offset points", fontsize=8.5, fontweight="bold", va="bottom")
    fig.subplots_adjust(left=0.02, right=0.98, top=0.86, bottom=0.02, hspace=0.62, wspace=0.05)
    return fig


def write_fig2(lmo: str | Path | None, ours: str | Path, out: str | Path, n: int = 3, lmo_split: str = "test") -> Path:
    """Draw :func:`draw_fig2` from the dataset directories ``lmo`` (a BOP LM-O, split ``lmo_split``; None
    or a missing directory: the row says so) and ``ours`` (a generated dataset) and write it atomically
    as a PNG of ``n * 400 x 760`` pixels to ``out``.

    Raises:
        DatasetError: a dataset cannot be read (one line naming the file).
    """
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..datasets.readers import open_dataset

    lmo_ds = open_dataset(lmo, split=lmo_split) if lmo is not None and Path(lmo).is_dir() else None
    fig = draw_fig2(lmo_ds, open_dataset(ours), n=n)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    plt.close(fig)
    return atomic_write_bytes(out, buf.getvalue())


def main(argv: list[str] | None = None) -> int:
    """``python -m sixdpose.reporting.fig2``: write Fig. 2 (see the module docstring); 0 on success, 1 with
    one line on stderr when a dataset cannot be read."""
    ap = argparse.ArgumentParser(prog="python -m sixdpose.reporting.fig2", description=__doc__.splitlines()[0])
    ap.add_argument("--lmo", default="../shared/data/lmo", help="BOP LM-O root (default: ../shared/data/lmo)")
    ap.add_argument("--lmo-split", default="test", help="its split (default: test)")
    ap.add_argument("--ours", required=True, help="a generated dataset directory")
    ap.add_argument("--out", required=True, help="the PNG to write, e.g. figures/demo/fig2_lmo_vs_ours.png")
    ap.add_argument("--frames", type=int, default=3, choices=range(1, 9), metavar="N",
                    help="frames per row, 1-8 (default: 3)")
    a = ap.parse_args(argv)
    try:
        path = write_fig2(a.lmo, a.ours, a.out, n=a.frames, lmo_split=a.lmo_split)
    except SixdposeError as e:
        print(f"fig2: {e}", file=sys.stderr)
        return 1
    print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
