"""Every registered reader, and how a pipeline reads the file of a dataset table.

Each reader module registers its readers (:func:`mixnav.io.registry.register_reader`);
they are found in the source and imported when a file names their format
(:mod:`mixnav.formats`): a new reader is its module, with no list to edit.
"""

from __future__ import annotations

from pathlib import Path

from .registry import KIND_TYPES, ReadOptions, Reader, formats, get_reader

__all__ = ["KIND_TYPES", "ReadOptions", "Reader", "formats", "get_reader", "read_table"]


def read_table(kind: str, table, folder: Path, key: str, source: str | None = None, path: Path | None = None):
    """Read the file a dataset table names: ``table.format`` picks the reader of ``kind``
    (an unknown one is a ConfigError naming ``<key>.format``), ``table.file`` relative to
    the data ``folder`` (or ``path``), the table's other keys are the reader's options."""
    reader = get_reader(kind, table.format, key=f"{key}.format", file=source)
    return reader(folder / table.file if path is None else path, ReadOptions(table, folder))
