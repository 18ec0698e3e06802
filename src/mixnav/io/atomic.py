"""Atomic writers: a results file is either complete or absent, never half written.

Each writer writes a temporary file in the target's folder, flushes and
fsyncs it, then renames it over the target (``os.replace`` is atomic on
POSIX and Windows when both names are on the same file system, hence the
same folder). On any error the temporary file is removed and the target is
left as it was. A process killed mid-write leaves its temporary file,
``.<name>.<pid>.<random>.tmp``: the writer's pid in the name lets a clean-up
remove it once that process has ended (:func:`remove_stale_temporaries`), and
never the file of a writer still running.
"""

from __future__ import annotations

import json
import math
import os
import re
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, BinaryIO, Iterable, Iterator

import numpy as np

__all__ = [
    "default_mode",
    "process_alive",
    "remove_stale_temporaries",
    "atomic_write_bytes",
    "atomic_write_text",
    "atomic_write_json",
    "atomic_write_dataframe",
    "atomic_savefig",
]


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


#: the process's umask, read once at import (reading it means setting it)
_UMASK = _umask()


def default_mode(base: int = 0o666) -> int:
    """The mode a new file (``0o666``) or folder (``0o777``) gets under the user's umask."""
    return base & ~_UMASK


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` runs on this machine (another user's counts as running).

    Windows: always True (nothing is taken for ended there): ``os.kill(pid, 0)`` would
    send CTRL_C_EVENT, not probe.
    """
    if os.name == "nt":
        return True
    if not 0 < pid < 2**31:     # no such process id (os.kill would overflow)
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:   # another user's process: alive
        return True
    return True


#: an atomic write's temporary file: ``.<name>.<pid>.<tempfile's 8 characters>.tmp``
_TEMPORARY = re.compile(r"^\..+\.([0-9]{1,10})\.[a-z0-9_]{8}\.tmp$")


def remove_stale_temporaries(folder: str | os.PathLike, ended: Iterable[int] = ()) -> int:
    """Remove the temporary files of atomic writes in ``folder`` whose writer has ended.

    A file ``.<name>.<pid>.<random>.tmp`` goes when no process ``pid`` runs on this machine,
    or ``pid`` is this process (call it when this process has no write in progress there),
    or is one of ``ended`` (processes known to have ended, e.g. the workers of a pool: on
    Windows the only way one is known); a ``.<name>.<random>.tmp`` without a pid (an older
    mixnav's) goes too. A writer on another host sharing the folder is not seen. What
    cannot be removed (a folder of that name, no permission) is left. Returns how many went.
    """
    ended = {int(p) for p in ended} | {os.getpid()}
    removed = 0
    for stray in Path(folder).glob(".*.tmp"):
        m = _TEMPORARY.match(stray.name)
        pid = int(m.group(1)) if m else None
        if pid is not None and pid not in ended and process_alive(pid):
            continue
        try:
            if stray.is_file() and not stray.is_symlink():
                stray.unlink()
                removed += 1
        except OSError:   # its writer finished meanwhile, or not ours to remove
            pass
    return removed


@contextmanager
def _atomic(path: str | os.PathLike) -> Iterator[BinaryIO]:
    """Yield a binary file that replaces ``path`` only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # Same folder as the target: os.replace must not cross file systems.
    tmp = tempfile.NamedTemporaryFile(dir=path.parent, prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp",
                                      delete=False)
    try:
        # NamedTemporaryFile creates 0600; the result gets what open() would give under the umask
        os.fchmod(tmp.fileno(), default_mode())
        with tmp as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp.name, path)
    except BaseException:
        # BaseException: a KeyboardInterrupt must not leave a stray temp file either.
        try:
            os.unlink(tmp.name)
        except FileNotFoundError:
            pass
        raise


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically.

    Parameters
    ----------
    path : str or PathLike
        Target file; its folder is created if missing.
    data : bytes
        The whole content of the file.
    """
    with _atomic(path) as fh:
        fh.write(data)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically, UTF-8 encoded.

    Parameters
    ----------
    path : str or PathLike
        Target file.
    text : str
        The whole content of the file.
    """
    atomic_write_bytes(path, text.encode("utf-8"))


def _find_non_finite(obj: Any, where: str = "$") -> str | None:
    """Key path (``$.a.b[2]``) of the first NaN or infinity in ``obj``, or None."""
    if isinstance(obj, (float, np.floating)):
        return where if not math.isfinite(obj) else None
    if isinstance(obj, np.ndarray):
        obj = obj.tolist()
    if isinstance(obj, dict):
        for k, v in obj.items():
            hit = _find_non_finite(v, f"{where}.{k}")
            if hit is not None:
                return hit
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            hit = _find_non_finite(v, f"{where}[{i}]")
            if hit is not None:
                return hit
    return None


def _json_default(obj: Any) -> Any:
    # numpy scalars and arrays slip into results easily; store them as plain numbers.
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"object of type {type(obj).__name__} is not JSON serializable")


def atomic_write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write ``obj`` as JSON (indent 2, keys in insertion order) atomically.

    Parameters
    ----------
    path : str or PathLike
        Target file.
    obj : JSON-serialisable object
        numpy scalars and arrays are converted to plain numbers and lists.

    Raises
    ------
    ValueError
        If a NaN or infinity occurs anywhere in ``obj``; the message names its
        key path (e.g. ``$.methods.ekf.horizontal_rmse_m``). Nothing is written.
    """
    bad = _find_non_finite(obj)
    if bad is not None:
        raise ValueError(f"refusing to write {path}: non-finite number at {bad}")
    text = json.dumps(obj, indent=2, sort_keys=False, allow_nan=False, default=_json_default)
    atomic_write_text(path, text + "\n")


def atomic_write_dataframe(path: str | os.PathLike, df) -> None:
    """Write a table atomically as CSV or Parquet, chosen by the suffix of ``path``.

    Parameters
    ----------
    path : str or PathLike
        Target file ending in ``.csv`` (``float_format='%.10g'``, no index) or
        ``.parquet`` (pyarrow, no index).
    df : pandas.DataFrame
        The table.

    Raises
    ------
    ValueError
        For any other suffix.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".csv":
        atomic_write_text(path, df.to_csv(index=False, float_format="%.10g"))
    elif suffix == ".parquet":
        with _atomic(path) as fh:
            df.to_parquet(fh, engine="pyarrow", index=False)
    else:
        raise ValueError(f"unknown table format '{path.suffix}' for {path}; use .csv or .parquet")


def atomic_savefig(fig, path: str | os.PathLike, **kw) -> None:
    """Save a matplotlib figure atomically.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : str or PathLike
        Target file; its suffix selects the format unless ``format`` is given.
    **kw
        Passed on to ``Figure.savefig`` (``dpi``, ``bbox_inches``, ...).
    """
    path = Path(path)
    # Writing into a file object loses the suffix, so pass the format explicitly.
    kw.setdefault("format", path.suffix.lstrip(".").lower() or "png")
    with _atomic(path) as fh:
        fig.savefig(fh, **kw)
