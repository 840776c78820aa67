"""The schema's vocabulary: ``setting`` fields, variants, and where a key sits in a file."""

from __future__ import annotations

import dataclasses
import math
import types
from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass
from pathlib import Path
from typing import Any, TypeVar, Union, get_args, get_origin

from ..errors import ConfigError

T = TypeVar("T")

#: Placeholder of a value derived from other keys in ``__schema_check__`` (documented by
#: ``setting(derived=...)``); never left in a loaded configuration.
DERIVED = math.nan

NONE_TYPE = type(None)

#: A discriminator key, ``resolve(value) -> class or None`` and ``known() -> {value: class}``.
Variants = tuple[str, Callable[[str], "type | None"], Callable[[], Mapping[str, type]]]


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
    variants: Variants | None = None
    derived: str = ""  # how a DERIVED default is computed (docs)
    expected: str = ""  # override of the "expected ..." text
    example: str = ""
    internal: bool = False  # not a key: set by the program, never read from a file
    nonempty: bool = False  # strings and arrays


def setting(
    default: Any = MISSING,
    *,
    doc: str,
    unit: str = "",
    ge: float | None = None,
    le: float | None = None,
    gt: float | None = None,
    lt: float | None = None,
    default_factory: Any = MISSING,
    path: str = "",
    variants: Variants | None = None,
    derived: str = "",
    expected: str = "",
    example: str = "",
    nonempty: bool = False,
) -> Any:
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
    spec = Spec(
        doc=doc,
        unit=unit,
        ge=ge,
        le=le,
        gt=gt,
        lt=lt,
        path=path,
        variants=variants,
        derived=derived,
        expected=expected,
        example=example,
        nonempty=nonempty,
    )
    kw: dict[str, Any] = {"metadata": {"schema": spec}}
    if default_factory is not MISSING:
        kw["default_factory"] = default_factory
    elif default is not MISSING:
        kw["default"] = default
    return dataclasses.field(**kw)


def variants(key: str, table: Mapping[str, type] | Callable[[], Mapping[str, type]]) -> Variants:
    """The ``variants`` of :func:`setting`: ``key``'s value picks the class from ``table``
    (a mapping, or a function returning one, for registries that grow at run time)."""
    known = table if callable(table) else (lambda: table)
    return key, (lambda value: known().get(value)), known


def internal(default: Any = MISSING, *, default_factory: Any = MISSING) -> Any:
    """A dataclass field that is not a configuration key (set by the program)."""
    kw: dict[str, Any] = {"metadata": {"schema": Spec(internal=True)}, "repr": False, "compare": False}
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
    #: what the indexes on the way mean to a reader (``trackers[1] is 'row-1'``)
    notes: tuple[str, ...] = ()

    def child(self, name: str) -> Where:
        return Where(self.file, f"{self.key}.{name}" if self.key else name, self.notes)

    def item(self, i: int, name: object = None) -> Where:
        """Item ``i`` of a list; ``name``: the item's own name, said in the message (the
        index counts from 0, which a reader of the file does not)."""
        key = f"{self.key}[{i}]"
        note = (f"{key} is {name!r}",) if isinstance(name, str) and name else ()
        return Where(self.file, key, self.notes + note)

    def error(self, expected: str, got: Any = None) -> ConfigError:
        """The error to raise here (``raise at.error("a positive number", value)``)."""
        return ConfigError(self.file, self.key, expected, got, notes=self.notes)

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


def is_dataclass_type(tp: Any) -> bool:
    return isinstance(tp, type) and dataclasses.is_dataclass(tp)


def union_args(tp: Any) -> tuple[Any, ...] | None:
    """The members of ``X | Y`` (or ``Optional[X]``), else None."""
    if get_origin(tp) in (Union, types.UnionType):
        return get_args(tp)
    return None
