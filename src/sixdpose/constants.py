"""Constants fixed by the paper (section III-B and III-C)."""

from __future__ import annotations

#: The 18 target objects, in the order of the merged-mask codes of section III-C.
#: The object id of a target (``obj_id``) is its 1-based position in this list. Other target sets
#: (``GenerationConfig.target_objects``, BOP models) follow :func:`merged_mask_codes`.
TARGET_OBJECTS: tuple[str, ...] = (
    "055_baseball",
    "056_tennis_ball",
    "072-a_toy_airplane",
    "019_pitcher_base",
    "040_large_marker",
    "021_bleach_cleanser",
    "077_rubiks_cube",
    "048_hammer",
    "008_pudding_box",
    "053_mini_soccer_ball",
    "011_banana",
    "006_mustard_bottle",
    "013_apple",
    "029_plate",
    "035_power_drill",
    "043_phillips_screwdriver",
    "032_knife",
    "042_adjustable_wrench",
)

#: Merged-mask code of each target: pixel value = code - instance number (section III-C).
MERGED_MASK_CODES: dict[str, int] = dict(
    zip(
        TARGET_OBJECTS, (14, 28, 42, 56, 70, 85, 99, 113, 127, 141, 155, 170, 184, 198, 212, 226, 240, 255), strict=True
    )
)


def merged_mask_codes(names, max_instances: int = 4) -> dict[str, int]:
    """Merged-mask codes of a target set: the paper's for its 18 targets, one rule for any other set.

    Rule: with ``N`` targets ordered by ``obj_id``, the ``k``-th (1-based) gets code
    ``floor(255 k / N)``; a pixel of instance ``i`` holds ``code - i``. For the paper's 18 targets in
    the paper's order this gives exactly the paper's codes 14, 28, ..., 255 (section III-C); a set of
    19 gives 13, 26, ..., 255.

    Args:
        names: target names in ``obj_id`` order. max_instances: instances of one object per scene.
    Returns:
        name -> code.
    Raises:
        ValueError: the set is empty or too large for uint8 codes (two codes closer than
            ``max_instances``, or the first code below ``max_instances``).
    """
    names = list(names)
    n = len(names)
    if n == 0:
        raise ValueError("no target objects")
    codes = [(255 * k) // n for k in range(1, n + 1)]
    if codes[0] < max_instances or min(b - a for a, b in zip([0] + codes, codes, strict=False)) < max_instances:
        raise ValueError(f"{n} target objects with up to {max_instances} instances each do not fit the uint8 merged "
                         f"masks (at most {255 // max_instances} targets)")
    return dict(zip(names, codes, strict=True))

#: At most this many instances of one object per scene (section III-C).
MAX_INSTANCES_PER_OBJECT = 4

# ---- thresholds of the evaluation protocol and of the stages that feed it (every default in the package
# ---- reads these; tests/test_layers.py fails on a copy typed elsewhere)
#: A ground-truth instance is scored (``evaluate``, the comparisons) and, with GT masks, registered by the
#: graph only if it has at least this many visible pixels.
MIN_VISIBLE_PX = 400

#: A pose is correct if its ADD(-S) error is below this fraction of the object's diameter (paper eq. 4: 10 %).
ADD_THRESHOLD = 0.1

#: The pose stages (``register``, ``predict-pose``) use a predicted mask only if its detection score is at
#: least this.
MIN_DETECTION_SCORE = 0.5

#: ``segment`` writes every detection scoring at least this (low, so that AP sees the whole precision-recall
#: curve); the pose stages then apply :data:`MIN_DETECTION_SCORE`.
DETECTION_SCORE_FLOOR = 0.05

#: Backbones of the segmentation stage's Mask R-CNN (torchvision ResNets, and MobileNetV3 for a lighter network
#: on a CPU), each with ImageNet weights ``sixdpose fetch-weights`` can put in the local cache.
SEG_BACKBONES = ("resnet18", "resnet34", "resnet50", "mobilenet_v3_large", "mobilenet_v3_small")

#: Attribution required by the YCB models' CC BY 4.0 licence.
YCB_ATTRIBUTION = (
    'Object models: "The YCB Object and Model Set" (Calli, Walsman, Singh, Srinivasa, Abbeel, Dollar; '
    "2015), http://ycb-benchmarks.s3-website-us-east-1.amazonaws.com/, licensed under Creative Commons "
    "Attribution 4.0 International (CC BY 4.0). This dataset contains renderings of these models and "
    "point clouds sampled from them."
)


def obj_id_of(name: str) -> int:
    """Return the 1-based object id of target ``name`` (paper order); raise ``KeyError`` otherwise."""
    try:
        return TARGET_OBJECTS.index(name) + 1
    except ValueError:
        raise KeyError(f"{name!r} is not one of the 18 target objects") from None
