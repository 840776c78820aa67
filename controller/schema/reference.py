"""The configuration reference, generated from the schema classes (``docs/config.md``)."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Mapping
from dataclasses import MISSING, dataclass
from typing import Literal, get_args, get_origin, get_type_hints

from .fields import NONE_TYPE, Spec, is_dataclass_type, keys_of, spec_of, union_args
from .words import range_text, toml_text, type_name


@dataclass(frozen=True)
class Row:
    key: str
    type: str
    unit: str
    default: str
    range: str
    doc: str


def _default_text(f: dataclasses.Field, spec: Spec) -> str:
    if spec.derived:
        return spec.derived
    if f.default is not MISSING:
        d = f.default
        if is_dataclass_type(type(d)):
            return "(table defaults)"
        return toml_text(d)
    if f.default_factory is not MISSING:
        d = f.default_factory()
        if is_dataclass_type(type(d)):
            return "(table defaults)"
        return toml_text(d)
    return "required"


def _sections(cls: type, prefix: str) -> Iterator[tuple[str, type, str]]:
    """(heading, class, note) of ``cls`` and of every table below it."""
    yield prefix, cls, ""
    hints = get_type_hints(cls)
    for f in keys_of(cls):
        spec = spec_of(f)
        tp = hints[f.name]
        args = union_args(tp)
        if args is not None:
            rest = [a for a in args if a is not NONE_TYPE]
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
        elif is_dataclass_type(item):
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
        args = union_args(tp)
        rest = [a for a in args if a is not NONE_TYPE] if args else [tp]
        inner = rest[0] if len(rest) == 1 else tp
        origin = get_origin(inner)
        item = get_args(inner)[0] if origin in (tuple, list) and get_args(inner) else inner
        if (
            is_dataclass_type(inner)
            or spec.variants is not None
            or (origin in (tuple, list) and (is_dataclass_type(item) or union_args(item)))
        ):
            continue  # a table of its own
        rng = range_text(spec)
        if get_origin(inner) is Literal:
            rng = ", ".join(toml_text(a) for a in get_args(inner))
        elif spec.path in ("file", "dir"):
            rng = f"existing {spec.path}"
        doc = spec.doc + (f" Example: `{spec.example}`." if spec.example else "")
        out.append(Row(f.name, type_name(tp), spec.unit, _default_text(f, spec), rng, doc))
    return out


def markdown(documents: Mapping[str, tuple[type, str]]) -> str:
    """The configuration reference: for each document (title -> (root class, intro)), one
    table per TOML table with every key, type, unit, default, range and meaning."""
    out = [
        "# Configuration reference",
        "",
        "Generated from the schema (`controller/schema.py` and the dataclasses it reads) by",
        "`heliotrack config docs`; a test fails when this file is stale.  Every file is TOML;",
        "unknown keys and tables are errors, and every error names the file, the key, what",
        "was expected and what was found.  Relative paths resolve against the file's folder.",
        "",
    ]
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
            out += ["| key | type | unit | default | range | meaning |", "|---|---|---|---|---|---|"]
            for r in table_rows:
                cells = [
                    f"`{r.key}`",
                    r.type,
                    r.unit,
                    f"`{r.default}`" if r.default != "required" else "required",
                    r.range,
                    r.doc,
                ]
                out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
            out.append("")
    return "\n".join(out).rstrip() + "\n"
