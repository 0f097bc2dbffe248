"""Strict configuration dataclasses: built from dicts, YAML files and ``key=value`` overrides.

Every configuration in PES (the scenario, each algorithm, each experiment) is a dataclass whose
defaults live in the class. This module turns untrusted input into such a dataclass:

* unknown keys are rejected, with the closest known key suggested;
* values are checked against the field's type hint (``int``, ``float``, ``bool``, ``str``,
  ``Literal[...]``, ``Optional``, ``tuple``/``list``) and never silently converted, except
  ``int`` -> ``float``;
* :func:`to_dict` turns a configuration back into plain values (a run writes them to YAML
  beside it).

Field documentation is the attribute docstring written under each field; :func:`field_docs`
reads it back so that ``docs/`` and ``--help`` show the same text as the code.
"""

from __future__ import annotations

import ast
import dataclasses
import difflib
import functools
import inspect
import math
import re
import textwrap
import types
import typing
from pathlib import Path
from typing import Any, Literal, TypeVar, Union, get_args, get_origin

import yaml

from pes.errors import ConfigError

T = TypeVar("T")


class _Loader(yaml.SafeLoader):
    """YAML 1.1 reads ``1e-4`` as a string; this loader reads it as a float, as users mean."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:\d+\.?\d*|\.\d+)[eE][-+]?\d+$"),
    list("-+0123456789."),
)


def _yaml_load(text: str) -> Any:
    return yaml.load(text, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass


def _type_name(hint: Any) -> str:
    origin = get_origin(hint)
    if origin is Literal:
        return " | ".join(repr(a) for a in get_args(hint))
    if origin in (Union, types.UnionType):
        return " | ".join(_type_name(a) for a in get_args(hint))
    if origin in (list, tuple):
        args = [a for a in get_args(hint) if a is not Ellipsis]
        inner = _type_name(args[0]) if args else "any"
        return f"list of {inner}"
    if hint is type(None):
        return "null"
    return getattr(hint, "__name__", str(hint))


def _coerce(value: Any, hint: Any, key: str) -> Any:
    """Check ``value`` against ``hint``; return it (lists become tuples for tuple hints)."""
    origin = get_origin(hint)
    if hint is Any:
        return value
    if origin is Literal:
        if value in get_args(hint) and type(value) is type(
            next(a for a in get_args(hint) if a == value)
        ):
            return value
        raise ConfigError(f"{key}: expected one of {_type_name(hint)}, got {value!r}")
    if origin in (Union, types.UnionType):
        errors = []
        for option in get_args(hint):
            try:
                return _coerce(value, option, key)
            except ConfigError as exc:
                errors.append(exc)
        raise ConfigError(f"{key}: expected {_type_name(hint)}, got {value!r}")
    if hint is type(None):
        if value is None:
            return None
        raise ConfigError(f"{key}: expected null, got {value!r}")
    if origin is dict:
        if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
            raise ConfigError(f"{key}: expected a mapping of names to values, got {value!r}")
        return dict(value)
    if origin in (list, tuple):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{key}: expected {_type_name(hint)}, got {value!r}")
        args = get_args(hint)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise ConfigError(f"{key}: expected {len(args)} values, got {len(value)}")
            return tuple(_coerce(v, a, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
        inner = args[0] if args else Any
        items = [_coerce(v, inner, f"{key}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if hint is bool:
        if isinstance(value, bool):
            return value
        raise ConfigError(f"{key}: expected true or false, got {value!r}")
    if hint is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise ConfigError(f"{key}: expected an integer, got {value!r}")
    if hint is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise ConfigError(f"{key}: expected a number, got {value!r}")
    if hint is str:
        if isinstance(value, str):
            return value
        raise ConfigError(f"{key}: expected a string, got {value!r}")
    if isinstance(value, hint):
        return value
    raise ConfigError(f"{key}: expected {_type_name(hint)}, got {value!r}")


def unknown_key(cls: type, key: object, names: list[str], label: str | None = None) -> ConfigError:
    """The error for a key that is not a field of ``cls`` (called ``label`` in the message,
    by default its class name), with the closest field suggested."""
    close = difflib.get_close_matches(str(key), names, n=1)
    hint = f" (did you mean '{close[0]}'?)" if close else ""
    return ConfigError(f"unknown {label or cls.__name__} key '{key}'{hint}")


def strict_keywords(cls: type[T]) -> type[T]:
    """Class decorator for a config dataclass: its constructor raises :class:`ConfigError`
    (naming the closest field) for an unknown keyword or too many positional values, where
    Python would raise ``TypeError``. Valid calls behave exactly as the dataclass's own
    ``__init__`` (which it wraps, keeping its signature for ``help`` and ``inspect``)."""
    original = cls.__init__  # type: ignore[misc]
    names = [f.name for f in dataclasses.fields(cls) if f.init]  # type: ignore[arg-type]

    @functools.wraps(original)
    def __init__(self: Any, *args: Any, **kwargs: Any) -> None:  # noqa: N807
        if len(args) > len(names):
            raise ConfigError(
                f"{cls.__name__} takes at most {len(names)} positional values, got {len(args)}"
            )
        for key in kwargs:
            if key not in names:
                raise unknown_key(cls, key, names)
            if key in names[: len(args)]:
                raise ConfigError(f"{cls.__name__} got two values for '{key}'")
        original(self, *args, **kwargs)

    cls.__init__ = __init__  # type: ignore[misc]
    return cls


def check_types(obj: Any) -> None:
    """Check every field of the dataclass instance ``obj`` against its type hint (as
    :func:`from_dict` does), raising :class:`ConfigError` naming the first ill-typed field."""
    hints = typing.get_type_hints(type(obj))
    for f in dataclasses.fields(obj):
        _coerce(getattr(obj, f.name), hints[f.name], f.name)


def from_dict(
    cls: type[T], values: dict[str, Any], *, base: T | None = None, label: str | None = None
) -> T:
    """Build ``cls`` from ``values``, rejecting unknown keys and ill-typed values.

    ``base`` (an instance of ``cls``) supplies the values not given; otherwise the defaults.
    ``label`` names the configuration in errors (default: the class name). The result is
    validated when the class has a ``validate()`` method.
    """
    label = label or cls.__name__
    if not isinstance(values, dict):
        raise ConfigError(f"{label} must be a mapping of keys to values, got {values!r}")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls) if f.init]
    for key in values:
        if key not in names:
            raise unknown_key(cls, key, names, label)
    checked = {key: _coerce(value, hints[key], key) for key, value in values.items()}
    obj = dataclasses.replace(base, **checked) if base is not None else cls(**checked)
    validate = getattr(obj, "validate", None)
    if callable(validate):
        validate()
    return obj


def check_finite(obj: Any, label: str) -> None:
    """Raise a :class:`ConfigError` naming the first float field of the dataclass ``obj`` that
    is NaN or infinite."""
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(f"{label}.{f.name} must be a finite number, got {value}")


def parse_override(text: str) -> tuple[str, Any]:
    """Split ``"key=value"``; the value is read as YAML (``3``, ``0.5``, ``true``, ``[1, 2]``)."""
    if "=" not in text:
        raise ConfigError(f"override '{text}' is not of the form key=value")
    key, raw = text.split("=", 1)
    key = key.strip()
    try:
        value = _yaml_load(raw) if raw.strip() else ""
    except yaml.YAMLError:
        value = raw
    return key, value


def read_text_file(path: str | Path, what: str = "file") -> str:
    """The text of ``path`` (UTF-8), or a one-line :class:`ConfigError` for a file that is
    missing, unreadable or not text (a binary file passed by mistake)."""
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{what} not found: {path}") from None
    except IsADirectoryError:
        raise ConfigError(f"{what} {path} is a folder, not a file") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a text file (is it the right {what}?)") from None
    except OSError as exc:
        raise ConfigError(f"cannot read {what} {path}: {exc.strerror or exc}") from None


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML mapping from ``path`` with a clear error for a missing or malformed file."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file not found: {path}")
    text = read_text_file(path, "config file")
    try:
        data = _yaml_load(text) or {}
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping of keys to values")
    return data


def to_dict(obj: Any) -> dict[str, Any]:
    """The dataclass as plain YAML/JSON-friendly values (tuples become lists)."""

    def plain(v: Any) -> Any:
        if isinstance(v, (list, tuple)):
            return [plain(x) for x in v]
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            return to_dict(v)
        if isinstance(v, dict):
            return {k: plain(x) for k, x in v.items()}
        return v

    return {f.name: plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}


def field_docs(cls: type) -> dict[str, str]:
    """The attribute docstring written under each field of the dataclass ``cls`` (or of the
    dataclass it inherits the field from)."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if dataclasses.is_dataclass(klass) and klass is not object:
            docs.update(_own_field_docs(klass))
    return docs


def _own_field_docs(cls: type) -> dict[str, str]:
    source = textwrap.dedent(inspect.getsource(cls))
    body = ast.parse(source).body[0].body  # type: ignore[attr-defined]
    docs: dict[str, str] = {}
    for node, nxt in zip(body, body[1:]):
        if (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and isinstance(nxt, ast.Expr)
            and isinstance(nxt.value, ast.Constant)
            and isinstance(nxt.value.value, str)
        ):
            docs[node.target.id] = " ".join(nxt.value.value.split())
    return docs


def field_table(cls: type) -> str:
    """A Markdown table of the fields of ``cls``: key, type, default and documentation."""
    hints = typing.get_type_hints(cls)
    docs = field_docs(cls)
    rows = ["| key | type | default | meaning |", "| --- | --- | --- | --- |"]
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        else:
            default = "required"
        if isinstance(default, tuple):
            default = list(default)
        type_name = _type_name(hints[f.name]).replace("|", "\\|")
        rows.append(f"| `{f.name}` | {type_name} | `{default!r}` | {docs.get(f.name, '')} |")
    return "\n".join(rows)
