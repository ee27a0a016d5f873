"""Statistics of a synthetic dataset, to compare with the paper's claims (section III-C)."""

from __future__ import annotations

from collections import Counter

import numpy as np

from .synthetic import SyntheticDataset


def dataset_statistics(ds: SyntheticDataset, min_px: int = 1) -> dict:
    """Per-image, per-object and camera statistics from ``gt.yml`` and ``manifest.json`` (no images read).

    Args:
        min_px: count an instance as present in an image if it has at least this many visible pixels.
    Returns:
        dict with arrays ``instances_per_image``, ``objects_per_image`` (distinct targets),
        ``camera_distance`` (m, camera to table-top centre), ``viewing_angle_deg`` (optical axis below
        the horizontal), ``camera_roll_deg``, ``instance_distance`` (m, camera to object origin), a
        Counter ``instances_per_object``, scene-level ``targets_per_scene``, ``noise_per_scene``,
        ``max_instances_of_one_object``, and ``off_table_fraction`` / ``left_scene_fraction`` over all
        dropped objects.
    """
    table_h = float(ds.manifest.get("config", {}).get("table_height", 0.75))
    inst_img, obj_img, dist, angle, roll, inst_dist = [], [], [], [], [], []
    per_obj: Counter = Counter()
    for im_id in ds.image_ids:
        e = ds.gt[im_id]
        objs = [o for o in e.get("objects") or [] if int(o.get("px_visib", 1)) >= min_px]
        inst_img.append(len(objs))
        obj_img.append(len({o["obj_name"] for o in objs}))
        per_obj.update(o["obj_name"] for o in objs)
        inst_dist.extend(float(np.linalg.norm(o["t"])) for o in objs)
        if "cam_R_WC" in e:
            R = np.asarray(e["cam_R_WC"])
            p = np.asarray(e["cam_t_WC"])
            dist.append(float(np.linalg.norm(p - [0.0, 0.0, table_h])))
            angle.append(float(np.degrees(np.arcsin(np.clip(-R[2, 2], -1, 1)))))
            # roll: angle between the image's "down" (+y_C) and the world's down projected on the image
            down = np.array([0.0, 0.0, -1.0])
            d_img = R.T @ down
            roll.append(float(np.degrees(np.arctan2(-d_img[0], d_img[1]))))
    t_scene, n_scene, max_same, n_obj, n_off, n_left = [], [], [], 0, 0, 0
    for sc in ds.manifest.get("scenes", {}).values():
        objs = sc["objects"]
        t_scene.append(sum(o["role"] == "target" for o in objs))
        n_scene.append(sum(o["role"] == "noise" for o in objs))
        c = Counter(o["name"] for o in objs)
        max_same.append(max(c.values()) if c else 0)
        n_obj += len(objs)
        n_off += sum(bool(o["off_table"]) for o in objs)
        n_left += sum(bool(o["left_scene"]) for o in objs)
    return {
        "images": len(ds.image_ids),
        "instances_per_image": np.array(inst_img),
        "objects_per_image": np.array(obj_img),
        "instances_per_object": per_obj,
        "camera_distance": np.array(dist),
        "viewing_angle_deg": np.array(angle),
        "camera_roll_deg": np.array(roll),
        "instance_distance": np.array(inst_dist),
        "targets_per_scene": np.array(t_scene),
        "noise_per_scene": np.array(n_scene),
        "max_instances_of_one_object": int(max(max_same, default=0)),
        "off_table_fraction": n_off / n_obj if n_obj else float("nan"),
        "left_scene_fraction": n_left / n_obj if n_obj else float("nan"),
    }


def claims_table(st: dict) -> list[tuple[str, str, str]]:
    """Rows ``(quantity, paper, this dataset)`` comparing :func:`dataset_statistics` to section III."""

    def rng(a):
        return f"{a.min()}-{a.max()}" if len(a) else "n/a"

    per_obj = st["instances_per_object"]
    return [
        ("images", "25,000", f"{st['images']:,}"),
        ("target objects per scene", "5-20", rng(st["targets_per_scene"])),
        ("noise objects per scene", "5-10", rng(st["noise_per_scene"])),
        ("max instances of one object", "4", str(st["max_instances_of_one_object"])),
        ("objects of interest", "18", str(len(per_obj))),
        ("visible instances per object (min)", "> 10,000 (at 25,000 images)",
         f"{min(per_obj.values()) if per_obj else 0:,}"),
        ("visible target instances per image (mean)", "-",
         f"{st['instances_per_image'].mean():.1f}" if st["images"] else "n/a"),
        ("camera distance to table centre, m", "varies",
         f"{np.percentile(st['camera_distance'], 5):.2f}-{np.percentile(st['camera_distance'], 95):.2f} (5-95%)"
         if len(st["camera_distance"]) else "n/a"),
        ("viewing angle below horizontal, deg", "random directions",
         f"{st['viewing_angle_deg'].min():.0f}-{st['viewing_angle_deg'].max():.0f}"
         if len(st["viewing_angle_deg"]) else "n/a"),
        ("camera roll, deg", "not upright",
         f"{st['camera_roll_deg'].min():.0f} to {st['camera_roll_deg'].max():.0f}"
         if len(st["camera_roll_deg"]) else "n/a"),
        ("objects off the table", "some", f"{100 * st['off_table_fraction']:.1f}%"),
    ]


def plot_statistics(st: dict):
    """A 2x3 figure of the distributions in :func:`dataset_statistics`."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 3, figsize=(14, 7))
    ax = ax.ravel()
    ax[0].hist(st["instances_per_image"], bins=range(0, int(st["instances_per_image"].max(initial=0)) + 2), color="C0")
    ax[0].set_xlabel("visible target instances per image")
    ax[1].hist(st["objects_per_image"], bins=range(0, int(st["objects_per_image"].max(initial=0)) + 2), color="C1")
    ax[1].set_xlabel("distinct target objects per image")
    names = sorted(st["instances_per_object"])
    ax[2].barh(names, [st["instances_per_object"][n] for n in names], color="C2")
    ax[2].set_xlabel("visible instances per object")
    ax[2].tick_params(axis="y", labelsize=6)
    ax[3].hist(st["camera_distance"], bins=30, color="C3")
    ax[3].set_xlabel("camera distance to table centre (m)")
    ax[4].hist(st["viewing_angle_deg"], bins=30, color="C4")
    ax[4].set_xlabel("viewing angle below horizontal (deg)")
    ax[5].hist(st["camera_roll_deg"], bins=30, color="C5")
    ax[5].set_xlabel(f"camera roll (deg); off table: {100 * st['off_table_fraction']:.1f}% of objects")
    for a in ax:
        a.set_ylabel("count")
    fig.tight_layout()
    return fig
