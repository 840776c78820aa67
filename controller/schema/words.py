"""What a key expects, in words: for error messages and the reference."""

from __future__ import annotations

import datetime as _dt
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal, get_args, get_origin

from .fields import NONE_TYPE, Spec, is_dataclass_type, union_args


def num_text(v: float) -> str:
    return str(int(v)) if float(v).is_integer() and abs(v) < 1e15 else f"{v:g}"


def range_text(spec: Spec) -> str:
    lo = (
        f"[{num_text(spec.ge)}"
        if spec.ge is not None
        else f"({num_text(spec.gt)}"
        if spec.gt is not None
        else ""
    )
    hi = (
        f"{num_text(spec.le)}]"
        if spec.le is not None
        else f"{num_text(spec.lt)})"
        if spec.lt is not None
        else ""
    )
    if lo and hi:
        return f"{lo}, {hi}"
    if spec.ge is not None:
        return f">= {num_text(spec.ge)}"
    if spec.gt is not None:
        return f"> {num_text(spec.gt)}"
    if spec.le is not None:
        return f"<= {num_text(spec.le)}"
    if spec.lt is not None:
        return f"< {num_text(spec.lt)}"
    return ""


def expected_text(tp: Any, spec: Spec) -> str:
    if spec.expected:
        return spec.expected
    unit = f" {spec.unit}" if spec.unit else ""
    rng = range_text(spec)
    if tp is float or tp is int:
        what = "a number" if tp is float else "an integer"
        return (
            f"{what} in {rng}{unit}"
            if rng.startswith(("[", "("))
            else f"{what}{' ' + rng if rng else ''}{unit}"
        )
    if get_origin(tp) is Literal:
        return "one of " + ", ".join(toml_text(a) for a in get_args(tp))
    args = union_args(tp)
    lits = [a for a in args or () if get_origin(a) is Literal]
    if lits:  # a choice, or an array of choices: name the choices, not "string"
        choices = ", ".join(toml_text(x) for a in lits for x in get_args(a))
        arrays = any(get_origin(a) in (tuple, list) for a in args or ())
        return f"one of {choices}" + (" (or an array of them)" if arrays else "")
    if get_origin(tp) in (tuple, list):
        each = f" each in {rng}" if rng else ""
        nonempty = "a non-empty " if spec.nonempty else "an "
        name = type_name(tp)
        return (f"{nonempty}array {name}" if name.startswith("[") else f"{nonempty}{name}") + each + unit
    article = {"string": "a ", "path": "a ", "boolean": "", "table": "a "}
    name = type_name(tp)
    if tp is str and spec.nonempty:
        return "a non-empty string"
    return article.get(name, "") + name


def type_name(tp: Any) -> str:
    """The TOML type of ``tp`` in words, for messages and the reference."""
    args = union_args(tp)
    if args is not None:
        rest = [a for a in args if a is not NONE_TYPE]
        return " or ".join(type_name(a) for a in rest)
    origin = get_origin(tp)
    if origin is Literal:
        return "string" if all(isinstance(a, str) for a in get_args(tp)) else "integer"
    if origin in (tuple, list):
        a = get_args(tp)
        if origin is tuple and not (len(a) == 2 and a[1] is Ellipsis):
            return "[" + ", ".join(type_name(x) for x in a) + "]"
        item = a[0] if a else Any
        if is_dataclass_type(item) or union_args(item):
            return "array of tables"
        return f"array of {type_name(item)}"
    names = {
        bool: "boolean",
        int: "integer",
        float: "number",
        str: "string",
        Path: "path",
        _dt.date: "date (YYYY-MM-DD)",
        dict: "table",
    }
    if tp in names:
        return names[tp]
    if origin in (dict, Mapping):
        return "table"
    if is_dataclass_type(tp):
        return "table"
    return getattr(tp, "__name__", str(tp))


def toml_text(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return num_text(v)
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(toml_text(x) for x in v) + "]"
    if isinstance(v, _dt.date):
        return v.isoformat()
    if v is None:
        return "(none)"
    return str(v)
