"""One configuration style for every stage: frozen dataclasses validated on construction, named
profiles, one ``--set key=value`` override mechanism, saved beside every output.

A stage's config is ``@dataclass(frozen=True) class XConfig(Config)``; every field is described in the
class docstring (a test checks it). Construction checks every field against its type hint (an int
field refuses 2.5 and "fast", a float field refuses NaN, infinities and strings; bools, tuples,
Optional and nested configs alike) and against the bounds declared with :func:`bounded` (field
metadata ``min`` / ``max``), then runs :meth:`Config.validate`, so an invalid config never exists,
whether built by ``--set``, a profile or code: bad values raise :class:`~sixdpose.errors.ConfigError`
naming the field, the value and what is allowed.

Overrides are ``key=value`` strings (``value`` parsed as YAML: ``3``, ``0.5``, ``true``, ``[1, 2]``,
``null``); nested configs take dotted keys (``camera.fov_y_deg=60``). Every subcommand that has a config
accepts them as ``--set key=value`` (repeatable); its dedicated flags (``--epochs`` ...) are shortcuts
for the same overrides.
"""

from __future__ import annotations

import dataclasses
import json
import math
import numbers
import re
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from .errors import ConfigError, OutputError
from .fileio import atomic_write_text, check_path_name

C = TypeVar("C", bound="Config")


class _Loader(yaml.SafeLoader):
    """YAML 1.2 numbers: ``1e-5`` is a float (PyYAML's YAML 1.1 rules need ``1.0e-5``)."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^[-+]?(?:\d+\.?\d*|\.\d+)[eE][-+]?\d+$"""),
    list("-+0123456789."),
)


def _yaml_value(text: str):
    return yaml.load(text, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass


def _plain(x):
    if isinstance(x, Config):
        return x.to_dict()
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x


def bounded(default, *, min=None, max=None, min_open: bool = False, max_open: bool = False):  # noqa: A002
    """A dataclass field with declared bounds: ``min``/``max`` (inclusive unless ``min_open``/``max_open``)
    for a number, or for each element of a tuple of numbers. Checked by every :class:`Config` on
    construction (so ``--set``, profiles and configs built in code alike) and used by the command line's
    flags for the same field (:func:`sixdpose.options.field_type`)."""
    md = {k: v for k, v in (("min", min), ("max", max)) if v is not None}
    md.update({k: True for k, v in (("min_open", min_open), ("max_open", max_open)) if v})
    return dataclasses.field(default=default, metadata=md)


def path_name(default: str):
    """A dataclass string field whose value becomes one component of a path (a split folder): checked
    on construction like the command line's names (:func:`sixdpose.fileio.check_path_name`)."""
    return dataclasses.field(default=default, metadata={"path_name": True})


def _is_int(v) -> bool:
    return isinstance(v, numbers.Integral) and not isinstance(v, bool)


def _is_real(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def _describe(hint) -> str:
    """What a type hint allows, in words."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        opts = [_describe(a) for a in args if a is not type(None)]
        return " or ".join(opts) + (" or null" if type(None) in args else "")
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_describe(args[0])}s"
        return f"a list of {len(args)} ({', '.join(_describe(a) for a in args)})"
    return {int: "an integer", float: "a finite number", bool: "true or false", str: "a string"}.get(
        hint, f"a {getattr(hint, '__name__', hint)}")


def _fits(hint, v, in_tuple: bool = False) -> bool:
    """Whether value ``v`` has the type ``hint`` (int, float, bool, str, tuples, Optional, nested configs)."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return any(v is None if a is type(None) else _fits(a, v, in_tuple) for a in args)
    if origin is tuple:
        if not isinstance(v, (list, tuple)):
            # a lone name where a tuple of names is expected is one name (validate wraps it)
            return args[-1] is Ellipsis and args[0] is str and (isinstance(v, str) or _is_int(v))
        if len(args) == 2 and args[1] is Ellipsis:
            return all(_fits(args[0], x, True) for x in v)
        return len(v) == len(args) and all(_fits(a, x, True) for a, x in zip(args, v, strict=True))
    if hint is bool:
        return isinstance(v, bool)
    if hint is int:
        return _is_int(v)
    if hint is float:
        return _is_real(v) and math.isfinite(float(v))
    if hint is str:
        return isinstance(v, str) or (in_tuple and _is_int(v))  # obj_ids as names (validate converts)
    if isinstance(hint, type):
        return isinstance(v, hint)
    return True


def _num(x) -> str:
    """A bound as written: 10000, not 1e+04."""
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else f"{x:g}"


def bounds_text(md) -> str:
    """Declared bounds in words (`` in [1, 10000]``, `` >= 0``) from field metadata (:func:`bounded`)."""
    lo, hi = md.get("min"), md.get("max")
    if lo is not None and hi is not None:
        return f" in {'(' if md.get('min_open') else '['}{_num(lo)}, {_num(hi)}{')' if md.get('max_open') else ']'}"
    if lo is not None:
        return f" {'>' if md.get('min_open') else '>='} {_num(lo)}"
    if hi is not None:
        return f" {'<' if md.get('max_open') else '<='} {_num(hi)}"
    return ""


def _in_bounds(md, v) -> bool:
    if isinstance(v, (list, tuple)):
        return all(_in_bounds(md, x) for x in v)
    if not _is_real(v):
        return True
    lo, hi = md.get("min"), md.get("max")
    if lo is not None and (v < lo or (md.get("min_open") and v == lo)):
        return False
    return not (hi is not None and (v > hi or (md.get("max_open") and v == hi)))


def field_metadata(cls, name: str):
    """The declared metadata of dataclass field ``name`` of ``cls`` (bounds of :func:`bounded`,
    :func:`path_name`): its own, else that of the nearest base class declaring it (a subclass that only
    changes a field's default keeps the base's bounds)."""
    for klass in cls.__mro__:
        f = klass.__dict__.get("__dataclass_fields__", {}).get(name)
        if f is not None and f.metadata:
            return f.metadata
    return {}


def check_fields(cfg) -> None:
    """Check every field of dataclass ``cfg`` against its type hint and its declared bounds
    (:func:`bounded`); raises :class:`ConfigError` naming the field, the value and what is allowed."""
    cls = type(cfg)
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cfg):
        v, hint, md = getattr(cfg, f.name), hints.get(f.name), field_metadata(cls, f.name)
        if hint is not None and not _fits(hint, v):
            raise ConfigError(f"{cls.__name__}: {f.name}={v!r} is not allowed: expected {_describe(hint)}"
                              f"{bounds_text(md)}")
        if md.get("path_name") and isinstance(v, str):
            try:
                check_path_name(v, f"{cls.__name__}: {f.name}")
            except OutputError as e:
                raise ConfigError(str(e)) from None
        if md and not _in_bounds(md, v):
            raise ConfigError(f"{cls.__name__}: {f.name}={v!r} is out of range: expected {_describe(hint)}"
                              f"{bounds_text(md)}")


class Config:
    """Base of the frozen dataclass configs (see the module docstring)."""

    def __post_init__(self):
        hints = typing.get_type_hints(type(self))
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, list) and "tuple" in str(hints.get(f.name, "")):
                object.__setattr__(self, f.name, tuple(v))
        check_fields(self)  # types and declared bounds first: validate() may compare values
        try:
            self.validate()
        except ConfigError:
            raise
        except (ValueError, TypeError) as e:
            raise ConfigError(f"{type(self).__name__}: {e}") from None

    def validate(self) -> None:
        """Raise ``ValueError`` (or :class:`ConfigError`) naming the first invalid field; run on construction,
        after every field was checked against its type hint and declared bounds (:func:`check_fields`)."""

    # -- (de)serialisation -------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Plain-data form (nested configs as dicts, tuples as lists) for YAML/JSON."""
        return {f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self)}

    @classmethod
    def from_dict(cls: type[C], d: dict) -> C:
        """Inverse of :meth:`to_dict`; unknown keys or bad values raise :class:`ConfigError`."""
        if not isinstance(d, dict):
            raise ConfigError(f"{cls.__name__}: expected a mapping, got {type(d).__name__}")
        fields = {f.name: f for f in dataclasses.fields(cls)}
        bad = sorted(set(d) - set(fields))
        if bad:
            raise ConfigError(f"{cls.__name__}: unknown config field(s) {', '.join(bad)}")
        hints = typing.get_type_hints(cls)
        kw = {}
        for k, v in d.items():
            sub = hints.get(k)
            if isinstance(sub, type) and issubclass(sub, Config) and isinstance(v, dict):
                v = sub.from_dict(v)
            kw[k] = v
        try:
            return cls(**kw)
        except TypeError as e:
            raise ConfigError(f"{cls.__name__}: {e}") from None

    def replace(self: C, **changes) -> C:
        """A copy with fields replaced (dotted names reach nested configs); validated.

        Raises:
            ConfigError: an unknown field name or an invalid value.
        """
        nested: dict[str, dict] = {}
        flat = {}
        for k, v in changes.items():
            head, _, rest = k.partition(".")
            if rest:
                nested.setdefault(head, {})[rest] = v
            else:
                flat[k] = v
        names = {f.name for f in dataclasses.fields(self)}
        bad = sorted((set(flat) | set(nested)) - names)
        if bad:
            raise ConfigError(f"{type(self).__name__}: unknown config field(s) {', '.join(bad)} "
                              f"(known: {', '.join(sorted(names))})")
        for head, sub in nested.items():
            cur = flat.get(head, getattr(self, head))
            if not isinstance(cur, Config):
                raise ConfigError(f"{type(self).__name__}.{head} has no sub-fields")
            flat[head] = cur.replace(**sub)
        for k, v in list(flat.items()):
            cur = getattr(self, k)
            if isinstance(cur, Config) and isinstance(v, dict):
                flat[k] = type(cur).from_dict(v)
        try:
            return dataclasses.replace(self, **flat)
        except TypeError as e:
            raise ConfigError(f"{type(self).__name__}: {e}") from None

    def to_yaml(self) -> str:
        """YAML text of :meth:`to_dict` (keys sorted)."""
        return yaml.safe_dump(self.to_dict(), sort_keys=True)

    def save(self, path: str | Path) -> Path:
        """Write the config atomically: JSON if ``path`` ends in ``.json``, else YAML."""
        path = Path(path)
        text = json.dumps(self.to_dict(), indent=2) + "\n" if path.suffix == ".json" else self.to_yaml()
        return atomic_write_text(path, text)

    @classmethod
    def load(cls: type[C], path: str | Path) -> C:
        """Read a config written by :meth:`save` (JSON or YAML); raises :class:`ConfigError` naming the file."""
        path = Path(path)
        try:
            d = _yaml_value(path.read_text())
        except FileNotFoundError:
            raise ConfigError(f"{path}: config file not found") from None
        except (OSError, yaml.YAMLError) as e:
            raise ConfigError(f"{path}: corrupt config ({str(e).splitlines()[0]})") from None
        try:
            return cls.from_dict(d)
        except ConfigError as e:
            raise ConfigError(f"{path}: {e}") from None


def check_overrides(cls: type[Config], overrides: dict | None, allowed: tuple[str, ...], what: str) -> dict:
    """``--set`` overrides of a command that may change only the fields ``allowed`` of config ``cls``
    (e.g. at inference), checked before any work: each allowed field against its type and bounds (on
    the default config). ``what`` names the command in the message.

    Returns:
        the overrides as a new dict.
    Raises:
        ConfigError: a field that is not allowed, or a bad value.
    """
    overrides = dict(overrides or {})
    bad = sorted(set(overrides) - set(allowed))
    if bad:
        raise ConfigError(f"{what} --set: {', '.join(bad)} cannot change at inference (allowed: {', '.join(allowed)})")
    if overrides:
        cls().replace(**overrides)
    return overrides


def parse_overrides(items) -> dict[str, Any]:
    """Parse ``["key=value", ...]`` (values as YAML) into a dict; raises :class:`ConfigError` on a bad item."""
    out: dict[str, Any] = {}
    for s in items or []:
        if "=" not in s:
            raise ConfigError(f"--set expects KEY=VALUE, got {s!r}")
        k, v = s.split("=", 1)
        try:
            out[k.strip()] = _yaml_value(v)
        except yaml.YAMLError:
            raise ConfigError(f"--set {k.strip()}: cannot parse value {v!r}") from None
    return out


def from_profile(profiles: dict[str, C], name: str, overrides: dict | None = None) -> C:
    """The named profile with ``overrides`` applied (``None`` is a value: it sets a field to null).

    Raises:
        ConfigError: an unknown profile, field or invalid value.
    """
    if name not in profiles:
        raise ConfigError(f"unknown profile {name!r} (choose from {', '.join(profiles)})")
    return profiles[name].replace(**overrides) if overrides else profiles[name]


def add_set_option(parser) -> None:
    """Add the shared ``--set KEY=VALUE`` option (repeatable) to an argparse (sub)parser."""
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="override one config field, e.g. --set lr=1e-4 (value parsed as YAML; repeatable; "
                             "dotted keys for nested fields)")


def undocumented_fields(cls) -> list[str]:
    """Names of the fields of config class ``cls`` that its docstring does not mention (for tests)."""
    doc = cls.__doc__ or ""
    return [f.name for f in dataclasses.fields(cls) if f.name not in doc]
