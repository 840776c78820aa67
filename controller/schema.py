"""One declarative configuration schema: typed dataclasses read by one generic validator.

Every file heliotrack reads (scenario and plant files, calibration bundles, sky settings)
is described by frozen dataclasses whose fields carry a :func:`setting` with the key's
documentation, unit and range.  :func:`load` walks a parsed TOML document against such a
class and either returns the dataclass or raises :class:`~controller.errors.ConfigError`
naming the file, the key path (``trackers[1].stow``), what was expected and what was
found.  Unknown keys and tables are errors.  ``docs/config.md`` is generated from the same
classes (:func:`markdown`), so the reference cannot drift from the code.

Supported field types: ``bool``, ``int``, ``float`` (finite; an integer is accepted),
``str``, ``Literal[...]``, ``pathlib.Path`` (resolved against the file's folder),
``datetime.date``, fixed tuples ``tuple[float, float]``, ``tuple[X, ...]``, nested
dataclasses (tables), ``tuple[Dataclass, ...]`` (arrays of tables), ``X | None``, a base
class whose subclasses are told apart by a discriminator key (``setting(variants=
variants("kind", {...}))``: link kinds, tracker types), and ``dict[str, Any]`` for
free-form tables.  Schema dataclasses are ``frozen=True, kw_only=True``.

Cross-field rules live on the class: a method ``__schema_check__(self, at: Where)`` runs
after the table is read and returns the (possibly completed) instance or raises through
``at.error(...)``.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
import tomllib
import types
from collections.abc import Callable, Iterator, Mapping
from dataclasses import MISSING, dataclass
from pathlib import Path
from typing import Any, Literal, TypeVar, Union, get_args, get_origin, get_type_hints

from .errors import ConfigError

__all__ = ["DERIVED", "Spec", "Where", "internal", "load", "load_file", "markdown",
           "read_toml", "rows", "setting", "variants"]

T = TypeVar("T")

#: Placeholder of a value derived from other keys in ``__schema_check__`` (documented by
#: ``setting(derived=...)``); never left in a loaded configuration.
DERIVED = math.nan

_NONE = type(None)


@dataclass(frozen=True)
class Spec:
    """What the documentation and the validator know about one key."""

    doc: str = ""
    unit: str = ""
    ge: float | None = None
    le: float | None = None
    gt: float | None = None
    lt: float | None = None
    #: "file" or "dir": a path that must exist; "new": a path whose folder is created later.
    path: str = ""
    #: For a union of dataclasses: the key that tells them apart, and a function mapping its
    #: value to the class (None for an unknown value), plus the known values for the docs.
    variants: tuple[str, Callable[[str], type | None], Callable[[], Mapping[str, type]]] | None = None
    derived: str = ""          # how a DERIVED default is computed (docs)
    expected: str = ""         # override of the "expected ..." text
    example: str = ""
    internal: bool = False     # not a key: set by the program, never read from a file
    nonempty: bool = False     # strings and arrays


def setting(default: Any = MISSING, *, doc: str, unit: str = "", ge: float | None = None,
            le: float | None = None, gt: float | None = None, lt: float | None = None,
            default_factory: Any = MISSING, path: str = "",
            variants: tuple[str, Callable[[str], type | None], Callable[[], Mapping[str, type]]] | None = None,
            derived: str = "", expected: str = "", example: str = "",
            nonempty: bool = False) -> Any:
    """A dataclass field that is a configuration key.

    Parameters
    ----------
    default, default_factory
        As for :func:`dataclasses.field`; neither makes the key required.  ``DERIVED``
        (with ``derived=`` saying how) marks a default computed by ``__schema_check__``.
    doc : str
        One sentence for the reference.
    unit : str
        Unit of a number ("s", "deg", "m/s").
    ge, le, gt, lt : float, optional
        Inclusive / exclusive bounds of a number, or of every number in an array.
    path : {"", "file", "dir", "new"}
        A :class:`~pathlib.Path` key: relative paths resolve against the file's folder;
        "file" and "dir" must exist.
    variants : (key, resolve, known), optional
        For a union of dataclasses (or one base class with registered kinds): the
        discriminator key, ``resolve(value) -> class or None`` and ``known() -> {value:
        class}`` for the reference.
    """
    if derived and default is MISSING:
        default = DERIVED
    spec = Spec(doc=doc, unit=unit, ge=ge, le=le, gt=gt, lt=lt, path=path, variants=variants,
                derived=derived, expected=expected, example=example, nonempty=nonempty)
    kw: dict[str, Any] = {"metadata": {"schema": spec}}
    if default_factory is not MISSING:
        kw["default_factory"] = default_factory
    elif default is not MISSING:
        kw["default"] = default
    return dataclasses.field(**kw)


def variants(key: str, table: Mapping[str, type] | Callable[[], Mapping[str, type]]
             ) -> tuple[str, Callable[[str], type | None], Callable[[], Mapping[str, type]]]:
    """The ``variants`` of :func:`setting`: ``key``'s value picks the class from ``table``
    (a mapping, or a function returning one, for registries that grow at run time)."""
    known = table if callable(table) else (lambda: table)
    return key, (lambda value: known().get(value)), known


def internal(default: Any = MISSING, *, default_factory: Any = MISSING) -> Any:
    """A dataclass field that is not a configuration key (set by the program)."""
    kw: dict[str, Any] = {"metadata": {"schema": Spec(internal=True)}, "repr": False,
                          "compare": False}
    if default_factory is not MISSING:
        kw["default_factory"] = default_factory
    else:
        kw["default"] = default
    return dataclasses.field(**kw)


# -- where we are in a document ------------------------------------------------------------
@dataclass(frozen=True)
class Where:
    """A position in a document: the file (for messages and relative paths) and key path."""

    file: str | None
    key: str = ""

    def child(self, name: str) -> "Where":
        return Where(self.file, f"{self.key}.{name}" if self.key else name)

    def item(self, i: int) -> "Where":
        return Where(self.file, f"{self.key}[{i}]")

    def error(self, expected: str, got: Any = None) -> ConfigError:
        """The error to raise here (``raise at.error("a positive number", value)``)."""
        return ConfigError(self.file, self.key, expected, got)

    @property
    def folder(self) -> Path:
        if self.file is None or self.file.startswith("<"):
            return Path.cwd()
        return Path(self.file).resolve().parent


def spec_of(f: dataclasses.Field) -> Spec:
    return f.metadata.get("schema") or Spec()


def keys_of(cls: type) -> list[dataclasses.Field]:
    """The fields of ``cls`` that are configuration keys, in declaration order."""
    return [f for f in dataclasses.fields(cls) if not spec_of(f).internal]


# -- reading -----------------------------------------------------------------------------
def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; a missing, unreadable, non-UTF-8 or invalid file is a ConfigError."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(path, "", f"a readable TOML file ({exc.strerror})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(path, "", f"UTF-8 text (byte {exc.start} is not)") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
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
            raise here.error(f"a value ({_expected(hints[f.name], spec_of(f))}); the key is missing")
    obj = cls(**kwargs)
    check = getattr(cls, "__schema_check__", None)
    if check is not None:
        obj = check(obj, at)
    return obj


def _is_dataclass_type(tp: Any) -> bool:
    return isinstance(tp, type) and dataclasses.is_dataclass(tp)


def _union_args(tp: Any) -> tuple[Any, ...] | None:
    if get_origin(tp) in (Union, types.UnionType):
        return get_args(tp)
    return None


def _value(tp: Any, v: Any, at: Where, spec: Spec) -> Any:
    args = _union_args(tp)
    if args is not None:
        rest = tuple(a for a in args if a is not _NONE)
        if len(rest) == 1:
            return _value(rest[0], v, at, spec)
        if spec.variants is not None:
            return _variant(v, at, spec)
        for a in rest:       # simple unions (str | date): the first that fits
            try:
                return _value(a, v, at, spec)
            except ConfigError:
                continue
        raise at.error(_expected(tp, spec), v)
    if spec.variants is not None and _is_dataclass_type(tp):
        return _variant(v, at, spec)
    origin = get_origin(tp)
    if origin is Literal:
        choices = get_args(tp)
        if v not in choices or isinstance(v, bool):
            raise at.error(_expected(tp, spec), v)
        return v
    if tp is bool:
        if not isinstance(v, bool):
            raise at.error("true or false", v)
        return v
    if tp is int:
        if not isinstance(v, int) or isinstance(v, bool):
            raise at.error(_expected(tp, spec), v)
        _bounds(v, at, spec, tp)
        return v
    if tp is float:
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            raise at.error(_expected(tp, spec), v)
        v = float(v)
        if not math.isfinite(v):
            raise at.error("a finite number", v)
        _bounds(v, at, spec, tp)
        return v
    if tp is str:
        if not isinstance(v, str) or (spec.nonempty and not v):
            raise at.error(_expected(tp, spec), v)
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
        raise at.error(_expected(tp, spec), v)
    if origin in (tuple, list):
        return _sequence(tp, v, at, spec)
    if origin in (dict, Mapping) or tp is dict:
        if not isinstance(v, dict):
            raise at.error("a table", v)
        return v
    if tp is Any:
        return v
    if _is_dataclass_type(tp):
        return _table(tp, v, at)
    raise TypeError(f"schema: unsupported type {tp!r} at {at.key}")


def _bounds(v: float, at: Where, spec: Spec, tp: Any) -> None:
    if ((spec.ge is not None and v < spec.ge) or (spec.le is not None and v > spec.le)
            or (spec.gt is not None and v <= spec.gt) or (spec.lt is not None and v >= spec.lt)):
        raise at.error(_expected(tp, spec), v)


def _sequence(tp: Any, v: Any, at: Where, spec: Spec) -> tuple[Any, ...]:
    if not isinstance(v, (list, tuple)):
        raise at.error(_expected(tp, spec), v)
    args = get_args(tp)
    if get_origin(tp) is tuple and not (len(args) == 2 and args[1] is Ellipsis):
        if len(v) != len(args):
            raise at.error(_expected(tp, spec), v)
        items = [_value(a, x, at.item(i), spec) for i, (a, x) in enumerate(zip(args, v))]
    else:
        item = args[0] if args else Any
        if spec.nonempty and not v:
            raise at.error(_expected(tp, spec), v)
        items = [_value(item, x, at.item(i), spec) for i, x in enumerate(v)]
    return tuple(items)


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
    if not isinstance(v, str) or not v:
        raise at.error("a path", v)
    p = Path(v).expanduser()
    if not p.is_absolute():
        p = (at.folder / p).resolve()
    if spec.path == "file" and not p.is_file():
        raise at.error("an existing file", str(p))
    if spec.path == "dir" and not p.is_dir():
        raise at.error("an existing folder", str(p))
    return p


# -- what is expected, in words --------------------------------------------------------------
def _num(v: float) -> str:
    return str(int(v)) if float(v).is_integer() and abs(v) < 1e15 else f"{v:g}"


def _range_text(spec: Spec) -> str:
    lo = f"[{_num(spec.ge)}" if spec.ge is not None else (f"({_num(spec.gt)}" if spec.gt is not None else "")
    hi = f"{_num(spec.le)}]" if spec.le is not None else (f"{_num(spec.lt)})" if spec.lt is not None else "")
    if lo and hi:
        return f"{lo}, {hi}"
    if spec.ge is not None:
        return f">= {_num(spec.ge)}"
    if spec.gt is not None:
        return f"> {_num(spec.gt)}"
    if spec.le is not None:
        return f"<= {_num(spec.le)}"
    if spec.lt is not None:
        return f"< {_num(spec.lt)}"
    return ""


def _expected(tp: Any, spec: Spec) -> str:
    if spec.expected:
        return spec.expected
    unit = f" {spec.unit}" if spec.unit else ""
    rng = _range_text(spec)
    if tp is float or tp is int:
        what = "a number" if tp is float else "an integer"
        return f"{what} in {rng}{unit}" if rng.startswith(("[", "(")) else \
            f"{what}{' ' + rng if rng else ''}{unit}"
    if get_origin(tp) is Literal:
        return "one of " + ", ".join(_toml(a) for a in get_args(tp))
    if get_origin(tp) in (tuple, list):
        each = f" each in {rng}" if rng else ""
        nonempty = "a non-empty " if spec.nonempty else "an "
        name = type_name(tp)
        return (f"{nonempty}array {name}" if name.startswith("[") else f"{nonempty}{name}") \
            + each + unit
    article = {"string": "a ", "path": "a ", "boolean": "", "table": "a "}
    name = type_name(tp)
    if tp is str and spec.nonempty:
        return "a non-empty string"
    return article.get(name, "") + name


def type_name(tp: Any) -> str:
    """The TOML type of ``tp`` in words, for messages and the reference."""
    args = _union_args(tp)
    if args is not None:
        rest = [a for a in args if a is not _NONE]
        return " or ".join(type_name(a) for a in rest)
    origin = get_origin(tp)
    if origin is Literal:
        return "string" if all(isinstance(a, str) for a in get_args(tp)) else "integer"
    if origin in (tuple, list):
        a = get_args(tp)
        if origin is tuple and not (len(a) == 2 and a[1] is Ellipsis):
            return "[" + ", ".join(type_name(x) for x in a) + "]"
        item = a[0] if a else Any
        if _is_dataclass_type(item) or _union_args(item):
            return "array of tables"
        return f"array of {type_name(item)}"
    names = {bool: "boolean", int: "integer", float: "number", str: "string", Path: "path",
             _dt.date: "date (YYYY-MM-DD)", dict: "table"}
    if tp in names:
        return names[tp]
    if origin in (dict, Mapping):
        return "table"
    if _is_dataclass_type(tp):
        return "table"
    return getattr(tp, "__name__", str(tp))


# -- the reference ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Row:
    key: str
    type: str
    unit: str
    default: str
    range: str
    doc: str


def _toml(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return _num(v)
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    if isinstance(v, _dt.date):
        return v.isoformat()
    if v is None:
        return "(none)"
    return str(v)


def _default_text(f: dataclasses.Field, spec: Spec) -> str:
    if spec.derived:
        return spec.derived
    if f.default is not MISSING:
        d = f.default
        if _is_dataclass_type(type(d)):
            return "(table defaults)"
        return _toml(d)
    if f.default_factory is not MISSING:
        d = f.default_factory()
        if _is_dataclass_type(type(d)):
            return "(table defaults)"
        return _toml(d)
    return "required"


def _sections(cls: type, prefix: str) -> Iterator[tuple[str, type, str]]:
    """(heading, class, note) of ``cls`` and of every table below it."""
    yield prefix, cls, ""
    hints = get_type_hints(cls)
    for f in keys_of(cls):
        spec = spec_of(f)
        tp = hints[f.name]
        args = _union_args(tp)
        if args is not None:
            rest = [a for a in args if a is not _NONE]
            tp = rest[0] if len(rest) == 1 else tp
        origin = get_origin(tp)
        array = origin in (tuple, list) and get_args(tp) and get_args(tp)[-1] is Ellipsis
        item = get_args(tp)[0] if array else tp
        name = f"{prefix}.{f.name}" if prefix else f.name
        heading = f"[[{name}]]" if array else f"[{name}]"
        if spec.variants is not None:
            key, _, known = spec.variants
            for value, sub in sorted(known().items()):
                yield from _sub_sections(sub, name, f'{heading} {key} = "{value}"')
        elif _is_dataclass_type(item):
            yield from _sub_sections(item, name, heading)


def _sub_sections(cls: type, name: str, heading: str) -> Iterator[tuple[str, type, str]]:
    first = True
    for sub_heading, sub_cls, note in _sections(cls, name):
        yield (heading if first else sub_heading), sub_cls, note
        first = False


def rows(cls: type) -> list[Row]:
    """The keys of one table (not of the tables below it), as reference rows."""
    hints = get_type_hints(cls)
    out = []
    for f in keys_of(cls):
        spec = spec_of(f)
        tp = hints[f.name]
        args = _union_args(tp)
        rest = [a for a in args if a is not _NONE] if args else [tp]
        inner = rest[0] if len(rest) == 1 else tp
        origin = get_origin(inner)
        item = get_args(inner)[0] if origin in (tuple, list) and get_args(inner) else inner
        if _is_dataclass_type(inner) or spec.variants is not None or (
                origin in (tuple, list) and (_is_dataclass_type(item) or _union_args(item))):
            continue   # a table of its own
        rng = _range_text(spec)
        if get_origin(inner) is Literal:
            rng = ", ".join(_toml(a) for a in get_args(inner))
        elif spec.path in ("file", "dir"):
            rng = f"existing {spec.path}"
        doc = spec.doc + (f" Example: `{spec.example}`." if spec.example else "")
        out.append(Row(f.name, type_name(tp), spec.unit, _default_text(f, spec), rng, doc))
    return out


def markdown(documents: Mapping[str, tuple[type, str]]) -> str:
    """The configuration reference: for each document (title -> (root class, intro)), one
    table per TOML table with every key, type, unit, default, range and meaning."""
    out = ["# Configuration reference", "",
           "Generated from the schema (`controller/schema.py` and the dataclasses it reads) by",
           "`heliotrack config docs`; a test fails when this file is stale.  Every file is TOML;",
           "unknown keys and tables are errors, and every error names the file, the key, what",
           "was expected and what was found.  Relative paths resolve against the file's folder.",
           ""]
    for title, (root, intro) in documents.items():
        out += [f"## {title}", "", intro, ""]
        for heading, cls, _ in _sections(root, ""):
            table_rows = rows(cls)
            if not table_rows:
                continue
            doc = " ".join((cls.__doc__ or "").strip().split("\n\n")[0].split()).replace("``", "`")
            out += [f"### `{heading}`" if heading else "### top level", ""]
            if doc and not doc.startswith(cls.__name__ + "("):
                out += [doc, ""]
            out += ["| key | type | unit | default | range | meaning |",
                    "|---|---|---|---|---|---|"]
            for r in table_rows:
                cells = [f"`{r.key}`", r.type, r.unit, f"`{r.default}`" if r.default != "required"
                         else "required", r.range, r.doc]
                out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
            out.append("")
    return "\n".join(out).rstrip() + "\n"


