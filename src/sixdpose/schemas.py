"""Schemas of the files sixdpose reads (pydantic v2), below every reader.

Each reader loads its file (JSON, YAML) and hands the data to :func:`check`, which validates keys, types
and ranges and raises the reader's own :class:`~sixdpose.errors.SixdposeError` subclass with one line
naming the file, the frame or entry, the key and what was expected. Nothing here supplies a default
for calibration: a BOP frame without ``depth_scale`` stays without one (the reader refuses to read its
depth), and a degenerate ``cam_K`` (non-positive or non-finite focal length) is refused.

Files covered:

* BOP: ``models_info.json`` (:data:`BOP_MODELS_INFO`), ``scene_camera.json`` (:data:`BOP_SCENE_CAMERA`,
  :class:`BopCameraEntry`), ``scene_gt.json`` (:data:`BOP_SCENE_GT`, :class:`BopGtEntry`),
  ``scene_gt_info.json`` (:data:`BOP_SCENE_GT_INFO`, :class:`BopGtInfoEntry`), ``camera.json``
  (:class:`BopCameraFile`).
* Synthetic layout: ``gt.yml`` (:data:`SYN_GT`, :class:`SynImage`), ``models/models_info.yml``
  (:data:`SYN_MODELS_INFO`), ``manifest.json`` (:data:`SYN_MANIFEST`).
* Predicted masks of ``sixdpose segment``: ``meta.json`` (:class:`PredictionMeta`) and
  ``coco_results.json`` (:data:`COCO_RESULTS`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    StringConstraints,
    TypeAdapter,
    ValidationError,
    field_validator,
)

from .errors import SixdposeError

# -- building blocks ------------------------------------------------------------------------------
_STRICT = ConfigDict(strict=True, extra="allow", allow_inf_nan=False)

#: A finite number (an int is accepted, a string or a bool is not).
Num = Annotated[float, Field(strict=True, allow_inf_nan=False)]
#: An integer id written as a JSON/YAML integer.
Int = Annotated[int, Field(strict=True)]
#: A JSON object key that is a decimal integer (BOP image / object ids).
IdKey = Annotated[str, StringConstraints(pattern=r"^[0-9]+$")]


def _plain_name(name: str) -> str:
    if not name or name in (".", "..") or "/" in name or "\\" in name or "\x00" in name:
        raise ValueError("must be a plain name (no path separator, not '.' or '..', not empty)")
    return name


#: A name that becomes one component of a path: no separator, not ``.``/``..``, not empty.
SafeName = Annotated[str, Field(strict=True), AfterValidator(_plain_name)]

Vec3 = Annotated[list[Num], Field(min_length=3, max_length=3)]
Mat9 = Annotated[list[Num], Field(min_length=9, max_length=9)]
Mat3x3 = Annotated[list[Vec3], Field(min_length=3, max_length=3)]


def _check_focal(K: list[float]) -> list[float]:
    """``K`` row-major (9,): focal lengths positive."""
    if not (K[0] > 0 and K[4] > 0):
        raise ValueError(f"focal lengths must be positive (fx={K[0]:g}, fy={K[4]:g})")
    return K


class _Model(BaseModel):
    model_config = _STRICT


# -- BOP ------------------------------------------------------------------------------------------
class BopModelInfo(_Model):
    """One object of ``models_info.json``: ``diameter`` in mm (> 0), optional ``obj_name`` and symmetries."""

    diameter: Annotated[float, Field(strict=True, gt=0, allow_inf_nan=False)]
    obj_name: SafeName | None = None
    symmetries_discrete: list[Mat9 | Annotated[list[Num], Field(min_length=16, max_length=16)]] | None = None
    symmetries_continuous: list[dict[str, Any]] | None = None


class BopCameraEntry(_Model):
    """One image of ``scene_camera.json``: ``cam_K`` (9 numbers, positive focal lengths) and
    ``depth_scale`` (mm per depth unit, > 0; None when the file has none: the depth cannot be read)."""

    cam_K: Mat9
    depth_scale: Annotated[float, Field(strict=True, gt=0, allow_inf_nan=False)] | None = None

    @field_validator("cam_K")
    @classmethod
    def _focal(cls, K):
        return _check_focal(K)


class BopGtEntry(_Model):
    """One instance of ``scene_gt.json``: ``obj_id`` (> 0), ``cam_R_m2c`` (9 numbers, row-major),
    ``cam_t_m2c`` (3 numbers, mm), optional ``inst`` (instance number, >= 0)."""

    obj_id: Annotated[int, Field(strict=True, gt=0)]
    cam_R_m2c: Mat9
    cam_t_m2c: Vec3
    inst: Annotated[int, Field(strict=True, ge=0)] | None = None


class BopGtInfoEntry(_Model):
    """One instance of ``scene_gt_info.json`` (only ``px_count_visib`` is read; >= 0 when present)."""

    px_count_visib: Annotated[int, Field(strict=True, ge=0)] | None = None


class BopCameraFile(_Model):
    """A dataset's ``camera.json``: ``fx fy cx cy`` (or a ``cam_K``), optional ``width height``, ``depth_scale``."""

    fx: Num | None = None
    fy: Num | None = None
    cx: Num | None = None
    cy: Num | None = None
    cam_K: Mat9 | None = None
    width: Annotated[int, Field(strict=True, gt=0)] | None = None
    height: Annotated[int, Field(strict=True, gt=0)] | None = None
    depth_scale: Annotated[float, Field(strict=True, gt=0, allow_inf_nan=False)] | None = None

    @field_validator("cam_K")
    @classmethod
    def _focal(cls, K):
        return K if K is None else _check_focal(K)


#: ``models_info.json``: obj_id (decimal string) -> :class:`BopModelInfo`.
BOP_MODELS_INFO = TypeAdapter(dict[IdKey, BopModelInfo])
#: Structure of ``scene_camera.json``: im_id -> entry (entries validated per frame).
BOP_SCENE_CAMERA = TypeAdapter(dict[IdKey, dict[str, Any]])
#: Structure of ``scene_gt.json`` / ``scene_gt_info.json``: im_id -> list of per-instance entries.
BOP_SCENE_GT = TypeAdapter(dict[IdKey, list[dict[str, Any]]])
BOP_SCENE_GT_INFO = BOP_SCENE_GT
BOP_GT_LIST = TypeAdapter(list[BopGtEntry])
BOP_GT_INFO_LIST = TypeAdapter(list[BopGtInfoEntry])


# -- synthetic layout -----------------------------------------------------------------------------
class SynObject(_Model):
    """One instance of a ``gt.yml`` image: ``obj_name`` (a path component), ``obj_id``, ``inst`` (>= 0),
    ``R`` (3x3), ``t`` (3, metres), ``px_visib`` (>= -1)."""

    obj_name: SafeName
    obj_id: Int
    inst: Annotated[int, Field(strict=True, ge=0)]
    R: Mat3x3
    t: Vec3
    px_visib: Annotated[int, Field(strict=True, ge=-1)] = -1


class SynImage(_Model):
    """One image of ``gt.yml``: ``scene_id`` (>= 0), ``cam_K`` (3x3, positive focal lengths), ``objects``."""

    scene_id: Annotated[int, Field(strict=True, ge=0)]
    cam_K: Mat3x3
    objects: list[SynObject] | None = None

    @field_validator("cam_K")
    @classmethod
    def _focal(cls, K):
        _check_focal([v for row in K for v in row])
        return K


class SynImageKey(_Model):
    """What opening ``gt.yml`` needs of each image (the rest is validated when the image is read)."""

    scene_id: Annotated[int, Field(strict=True, ge=0)]


class SynModelInfo(_Model):
    """One object of ``models/models_info.yml``: ``obj_id``, ``diameter`` in metres (> 0), ``symmetric``."""

    obj_id: Int
    diameter: Annotated[float, Field(strict=True, gt=0, allow_inf_nan=False)]
    symmetric: Annotated[bool, Field(strict=True)] = False


#: ``gt.yml`` structure: image number -> image (entries validated per image).
SYN_GT = TypeAdapter(dict[Annotated[int, Field(strict=True, ge=0)], SynImageKey])
SYN_IMAGE = TypeAdapter(SynImage)
#: ``models/models_info.yml``: object name (a path component) -> :class:`SynModelInfo`.
SYN_MODELS_INFO = TypeAdapter(dict[SafeName, SynModelInfo])
#: ``manifest.json``: a JSON object.
SYN_MANIFEST = TypeAdapter(dict[str, Any])


# -- predicted masks ------------------------------------------------------------------------------
class PredictionMeta(_Model):
    """``meta.json`` of a prediction directory (``sixdpose segment``); each field is checked when present
    (a consumer that needs one asks for it). ``dataset_fingerprint`` is absent in directories written
    before it was recorded."""

    checkpoint: str | None = None
    epoch: Int | None = None
    classes: list[Any] | None = None
    score_thresh: Annotated[float, Field(strict=True, ge=0, allow_inf_nan=False)] | None = None  # > 1: keep none
    data: str | None = None
    split: str | None = None
    subset: str | None = None
    images: list[Annotated[list[Int], Field(min_length=2, max_length=4)]] | None = None
    dataset_fingerprint: Annotated[str, StringConstraints(pattern=r"^[0-9a-f]{64}$")] | None = None


class CocoRle(_Model):
    """A COCO run-length encoded mask: ``size`` ``[h, w]``, ``counts`` (compressed string or list)."""

    size: Annotated[list[Annotated[int, Field(strict=True, ge=0)]], Field(min_length=2, max_length=2)]
    counts: str | list[Annotated[int, Field(strict=True, ge=0)]]


class CocoDetection(_Model):
    """One entry of ``coco_results.json``."""

    image_id: Int
    category_id: Int
    segmentation: CocoRle
    bbox: Annotated[list[Num], Field(min_length=4, max_length=4)]
    score: Annotated[float, Field(strict=True, ge=0, le=1, allow_inf_nan=False)]


COCO_RESULTS = TypeAdapter(list[CocoDetection])


# -- validation -----------------------------------------------------------------------------------
def _loc(loc: tuple) -> str:
    out = ""
    for p in loc:
        if p == "[key]":
            out += " (the key)"
        elif isinstance(p, int):
            out += f"[{p}]"
        else:
            out += f".{p}" if out else str(p)
    return out


def describe(e: ValidationError, item: str = "") -> str:
    """The first problem of a pydantic error as ``key: what was expected (got value)``, one line.

    ``item`` names what the first level of keys is (e.g. ``"image"``): ``image 12: cam_K[0]: ...``.
    """
    err = e.errors(include_url=False)[0]
    loc = tuple(err.get("loc", ()))
    head = ""
    if item and loc:
        head, loc = f"{item} {loc[0]}: ", loc[1:]
        if loc[:1] == ("[key]",):
            head, loc = f"{item} key {err.get('input')!r}: ", ()
    where = _loc(loc)
    msg = err.get("msg", "invalid").replace("\n", " ").removeprefix("Value error, ")
    got = err.get("input")
    if err.get("type") == "missing":
        text = f"missing field {where!r}" if where else "missing field"
    else:
        shown = repr(got)
        if len(shown) > 60:
            shown = shown[:57] + "..."
        text = f"{where + ': ' if where else ''}{msg} (got {shown})"
    more = len(e.errors()) - 1
    return head + text + (f" (and {more} more problem{'s' if more > 1 else ''})" if more > 0 else "")


def check(schema, data, path: str | Path, error: type[SixdposeError], where: str = "", item: str = ""):
    """Validate ``data`` (loaded from ``path``) against ``schema`` (a :class:`~pydantic.TypeAdapter` or a
    model class) and return the validated value.

    Args:
        schema: the schema. data: the loaded value. path: the file, for the message. error: the
            exception class to raise. where: what part of the file ``data`` is, e.g. ``"image 12: "``.
        item: what the keys of a top-level mapping are, e.g. ``"image"`` (see :func:`describe`).
    Raises:
        ``error``: one line ``<path>: <where><key>: <what was expected> (got <value>)``.
    """
    try:
        if isinstance(schema, TypeAdapter):
            return schema.validate_python(data)
        return schema.model_validate(data)
    except ValidationError as e:
        raise error(f"{path}: {where}{describe(e, item)}") from None


def safe_name(name: str, what: str, error: type[SixdposeError] = SixdposeError) -> str:
    """``name`` if it can be used as one path component (no separator, not ``.``/``..``, not empty,
    not absolute); else ``error`` naming ``what`` (e.g. ``"--split"``)."""
    try:
        return _plain_name(name if isinstance(name, str) else "")
    except ValueError as e:
        raise error(f"{what}: {name!r} {e}") from None
