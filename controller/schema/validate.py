"""The one generic validator: a parsed TOML document against a schema dataclass."""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
import tomllib
from collections.abc import Mapping
from dataclasses import MISSING
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin, get_type_hints

from ..errors import ConfigError
from .fields import NONE_TYPE, Spec, Where, is_dataclass_type, keys_of, spec_of, union_args
from .words import expected_text

T = TypeVar("T")


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; a missing, unreadable, non-UTF-8 or invalid file is a ConfigError."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(path, "", f"a readable TOML file ({exc.strerror})") from None
    try:
        text = data.decode("utf-8-sig")  # Notepad's byte-order mark is not a TOML error
    except UnicodeDecodeError as exc:
        raise ConfigError(path, "", f"UTF-8 text (byte {exc.start} is not)") from None
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise ConfigError(path, "", "valid TOML (arrays or tables nested too deep)") from None
    except ValueError as exc:  # TOMLDecodeError, and an integer past Python's 4300 digits
        raise ConfigError(path, "", f"valid TOML ({exc})") from None


def load_file(schema: type[T], path: str | Path) -> T:
    """Read ``path`` and validate it against ``schema``."""
    return load(schema, read_toml(path), str(path))


def load(schema: type[T], data: Any, file: str | Path | None = None, key: str = "") -> T:
    """Validate a parsed document (or one table of it) against the dataclass ``schema``.

    An internal field named ``file`` is set to ``file``.
    """
    at = Where(str(file) if file is not None else None, key)
    obj = _table(schema, data, at)
    if file is not None and any(f.name == "file" for f in dataclasses.fields(obj)):  # type: ignore[arg-type]
        obj = dataclasses.replace(obj, file=str(file))  # type: ignore[type-var]
    return obj


def _table(cls: type[T], data: Any, at: Where) -> T:
    if not isinstance(data, dict):
        raise at.error("a table", data)
    fields = keys_of(cls)
    names = {f.name for f in fields}
    for k in data:
        if k not in names:
            known = ", ".join(sorted(names))
            raise at.child(k).error(f"one of the known keys ({known})", "unknown key")
    hints = get_type_hints(cls)
    kwargs: dict[str, Any] = {}
    for f in fields:
        here = at.child(f.name)
        if f.name in data:
            kwargs[f.name] = _value(hints[f.name], data[f.name], here, spec_of(f))
        elif f.default is MISSING and f.default_factory is MISSING:
            raise here.error(f"a value ({expected_text(hints[f.name], spec_of(f))}); the key is missing")
        elif isinstance(f.default_factory, type) and hasattr(f.default_factory, "__schema_check__"):
            # an absent table is its defaults completed by its own rules (derived keys: a
            # plant file without [control] got a NaN watchdog timeout and lead)
            kwargs[f.name] = _table(f.default_factory, {}, here)
    obj = cls(**kwargs)
    check = getattr(cls, "__schema_check__", None)
    if check is not None:
        try:
            obj = check(obj, at)
        except (ValueError, OverflowError, OSError, RuntimeError) as exc:
            # a cross-field rule tripped on a value it did not foresee (a path it cannot
            # expand or resolve, a number too large for arithmetic): still the file's fault
            raise at.error(f"usable settings ({exc})") from None
    return obj


def _value(tp: Any, v: Any, at: Where, spec: Spec) -> Any:
    args = union_args(tp)
    if args is not None:
        rest = tuple(a for a in args if a is not NONE_TYPE)
        if len(rest) == 1:
            return _value(rest[0], v, at, spec)
        if spec.variants is not None:
            return _variant(v, at, spec)
        for a in rest:  # simple unions (str | date): the first that fits
            try:
                return _value(a, v, at, spec)
            except ConfigError:
                continue
        raise at.error(expected_text(tp, spec), v)
    if spec.variants is not None and is_dataclass_type(tp):
        return _variant(v, at, spec)
    origin = get_origin(tp)
    if origin is Literal:
        choices = get_args(tp)
        if v not in choices or isinstance(v, bool):
            raise at.error(expected_text(tp, spec), v)
        return v
    if tp is bool:
        if not isinstance(v, bool):
            raise at.error("true or false", v)
        return v
    if tp is int:
        if not isinstance(v, int) or isinstance(v, bool):
            raise at.error(expected_text(tp, spec), v)
        _bounds(v, at, spec, tp)
        return v
    if tp is float:
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            raise at.error(expected_text(tp, spec), v)
        try:
            v = float(v)
        except OverflowError:  # an integer beyond the float range
            raise at.error("a finite number", "an integer too large for a float") from None
        if not math.isfinite(v):
            raise at.error("a finite number", v)
        _bounds(v, at, spec, tp)
        return v
    if tp is str:
        if not isinstance(v, str) or (spec.nonempty and not v):
            raise at.error(expected_text(tp, spec), v)
        return v
    if tp is Path:
        return _path(v, at, spec)
    if tp is _dt.date:
        if isinstance(v, _dt.date) and not isinstance(v, _dt.datetime):
            return v
        if isinstance(v, str):
            try:
                return _dt.date.fromisoformat(v)
            except ValueError:
                pass
        raise at.error(expected_text(tp, spec), v)
    if origin in (tuple, list):
        return _sequence(tp, v, at, spec)
    if origin in (dict, Mapping) or tp is dict:
        if not isinstance(v, dict):
            raise at.error("a table", v)
        return v
    if tp is Any:
        return v
    if is_dataclass_type(tp):
        return _table(tp, v, at)
    raise TypeError(f"schema: unsupported type {tp!r} at {at.key}")


def _bounds(v: float, at: Where, spec: Spec, tp: Any) -> None:
    if (
        (spec.ge is not None and v < spec.ge)
        or (spec.le is not None and v > spec.le)
        or (spec.gt is not None and v <= spec.gt)
        or (spec.lt is not None and v >= spec.lt)
    ):
        raise at.error(expected_text(tp, spec), v)


def _sequence(tp: Any, v: Any, at: Where, spec: Spec) -> tuple[Any, ...]:
    if not isinstance(v, (list, tuple)):
        raise at.error(expected_text(tp, spec), v)
    args = get_args(tp)
    if get_origin(tp) is tuple and not (len(args) == 2 and args[1] is Ellipsis):
        if len(v) != len(args):
            raise at.error(expected_text(tp, spec), v)
        items = [_value(a, x, at.item(i), spec) for i, (a, x) in enumerate(zip(args, v))]
    else:
        item = args[0] if args else Any
        if spec.nonempty and not v:
            raise at.error(expected_text(tp, spec), v)
        items = [_value(item, x, at.item(i, _name(x)), spec) for i, x in enumerate(v)]
    return tuple(items)


def _name(item: Any) -> object:
    """A table's ``name`` (trackers, links), to say which one an index means."""
    return item.get("name") if isinstance(item, dict) else None


def _variant(v: Any, at: Where, spec: Spec) -> Any:
    if not isinstance(v, dict):
        raise at.error("a table", v)
    assert spec.variants is not None
    key, resolve, known = spec.variants
    if key not in v:
        raise at.child(key).error(f"one of {', '.join(sorted(known()))}; the key is missing")
    cls = resolve(v[key]) if isinstance(v[key], str) else None
    if cls is None:
        raise at.child(key).error(f"one of {', '.join(sorted(known()))}", v[key])
    return _table(cls, v, at)


def _path(v: Any, at: Where, spec: Spec) -> Path:
    return checked_path(v, at, spec.path)


def checked_path(v: Any, at: Where, kind: str = "") -> Path:
    """``v`` as a path, from the file's folder when relative: ``kind`` "file" or "dir"
    must exist, "new" must not be a folder; an error at ``at`` that says why otherwise."""
    if not isinstance(v, str) or not v:
        raise at.error("a path", v)
    if "\x00" in v:
        raise at.error("a path (without NUL characters)", v)
    try:
        p = Path(v).expanduser()
        if not p.is_absolute():
            p = (at.folder / p).resolve()
        if kind == "file" and not p.is_file():
            raise at.error("an existing file", str(p))
        if kind == "dir" and not p.is_dir():
            raise at.error("an existing folder", str(p))
        if kind == "new" and p.is_dir():  # a file goes there: a folder would be moved aside
            raise at.error("a file's path (this is a folder)", str(p))
    except RuntimeError:  # "~user" of no known user
        raise at.error("a path (its '~' names no user with a home folder)", v) from None
    except OSError as exc:  # a name too long, a loop of links...
        raise at.error(f"a usable path ({exc.strerror or exc})", v) from None
    return p
