"""One configuration style for every stage: frozen dataclasses validated on construction, named
profiles, one ``--set key=value`` override mechanism, saved beside every output.

A stage's config is ``@dataclass(frozen=True) class XConfig(Config)``; every field is described in the
class docstring (a test checks it). Construction runs :meth:`Config.validate`, so an invalid config
never exists: bad values raise :class:`~sixdpose.errors.ConfigError` naming the field.

Overrides are ``key=value`` strings (``value`` parsed as YAML: ``3``, ``0.5``, ``true``, ``[1, 2]``,
``null``); nested configs take dotted keys (``camera.fov_y_deg=60``). Every subcommand that has a config
accepts them as ``--set key=value`` (repeatable); its dedicated flags (``--epochs`` ...) are shortcuts
for the same overrides.
"""

from __future__ import annotations

import dataclasses
import json
import re
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from .errors import ConfigError
from .fileio import atomic_write_text

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


class Config:
    """Base of the frozen dataclass configs (see the module docstring)."""

    def __post_init__(self):
        hints = typing.get_type_hints(type(self))
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, list) and "tuple" in str(hints.get(f.name, "")):
                object.__setattr__(self, f.name, tuple(v))
        try:
            self.validate()
        except ConfigError:
            raise
        except (ValueError, TypeError) as e:
            raise ConfigError(f"{type(self).__name__}: {e}") from None

    def validate(self) -> None:
        """Raise ``ValueError`` (or :class:`ConfigError`) naming the first invalid field; run on construction."""

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
            raise ConfigError(f"{type(self).__name__}: unknown config field(s) {', '.join(bad)} (known: {', '.join(sorted(names))})")
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
