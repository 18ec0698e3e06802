"""Safe file-name components: the rule every name that becomes a file name follows.

A method name becomes ``solution_<name>.csv``, so the config checks it when the file
is loaded and the output folders (:mod:`mixnav.io.outdir`) check every name they
write; the rule sits here, below both, so the config need not import ``io``.
"""

from __future__ import annotations

import re

from .errors import ArgumentError

#: longest file name written (bytes; file systems allow 255)
MAX_NAME_BYTES = 200
_NAME = re.compile(r"^[A-Za-z0-9_+\-][A-Za-z0-9_.+\-]*$")


def safe_name(name: str, what: str = "file name") -> str:
    """``name`` when it is a safe single file-name component, else an ArgumentError.

    Safe: ASCII letters, digits, ``_ + - .``; not starting with ``.``; no ``..``;
    at most :data:`MAX_NAME_BYTES` bytes. ASCII only: a name with an accent (``café``)
    is written in different bytes by file systems that normalise Unicode differently (macOS
    decomposes it), so the file it names could not be found by the same name everywhere.
    """
    if not isinstance(name, str) or not name:
        raise ArgumentError(f"{what} must be a non-empty string, got {name!r}", what)
    if ".." in name or not _NAME.match(name) or len(name.encode("utf-8")) > MAX_NAME_BYTES:
        raise ArgumentError(f"{what} {name!r} cannot be part of a file name: use ASCII letters, digits "
                            f"and _ + - . only (not starting with '.', no '..', at most "
                            f"{MAX_NAME_BYTES} characters)", what)
    return name
