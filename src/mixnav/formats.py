"""The file formats a dataset file may name, per reader kind, found without importing a reader.

A reader registers itself in its own module of :mod:`mixnav.io`
(``@register_reader("imu", "psins")``, :mod:`mixnav.io.registry`). This module reads those
registrations from the package's source text, as the estimator registry reads its own
(:func:`mixnav.filters.registry.find_registrations`): the config checks a ``format`` key at
load time without importing io (the layers keep their order, nothing compiles), and io
imports only the module that holds the format a file names. A reader registered at run
time (another package's) is added by ``register_reader`` (:func:`add`). So a new reader is
its module and nothing else: no import line, no list in a schema.
"""

from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path

#: a module-level reader registration in mixnav/io: ``@register_reader("kind", "format")``
_REGISTRATION = re.compile(r'^@register_reader\(\s*"([^"]+)"\s*,\s*"([^"]+)"\s*\)', re.M)
#: (kind, format) -> the module that registered it at run time (None: not known)
_ADDED: dict[tuple[str, str], str | None] = {}


def find_readers(folder, package: str) -> dict[tuple[str, str], str]:
    """(kind, format) -> module of every module-level registration in ``folder`` (the files of
    ``package``), read from the source, in file and line order."""
    found: dict[tuple[str, str], str] = {}
    for path in sorted(Path(folder).glob("*.py")):
        for kind, fmt in _REGISTRATION.findall(path.read_text(encoding="utf-8")):
            found.setdefault((kind, fmt), f"{package}.{path.stem}")
    return found


@lru_cache(maxsize=1)
def builtin_readers() -> dict[tuple[str, str], str]:
    """(kind, format) -> the mixnav.io module that reads it (imported only when a file names it)."""
    return find_readers(Path(__file__).resolve().parent / "io", "mixnav.io")


def add(kind: str, fmt: str, module: str | None = None) -> None:
    """Record a reader registered at run time (called by ``mixnav.io.registry.register_reader``)."""
    _ADDED.setdefault((kind, fmt), module)


def known_formats(kind: str) -> tuple[str, ...]:
    """Every format of ``kind``: the built-in readers', then those registered at run time."""
    names = [f for k, f in builtin_readers() if k == kind]
    return tuple(names + [f for k, f in _ADDED if k == kind and f not in names])


def check_format(kind: str, value) -> str:
    """``value`` if it names a reader of ``kind``; else a ValueError listing the formats."""
    if not isinstance(value, str) or value not in known_formats(kind):
        raise ValueError(f"unknown {kind} format {value!r} (registered: {', '.join(known_formats(kind)) or 'none'})")
    return value
