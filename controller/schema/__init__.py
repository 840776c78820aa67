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

from .fields import DERIVED, Spec, Where, internal, keys_of, setting, spec_of, variants
from .reference import Row, markdown, rows
from .validate import checked_path, load, load_file, read_toml
from .words import type_name

__all__ = [
    "checked_path",
    "DERIVED",
    "Row",
    "Spec",
    "Where",
    "internal",
    "keys_of",
    "load",
    "load_file",
    "markdown",
    "read_toml",
    "rows",
    "setting",
    "spec_of",
    "type_name",
    "variants",
]
