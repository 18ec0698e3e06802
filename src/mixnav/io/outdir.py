"""Output folders a user can trust: never mixed, never half written, nothing outside.

The policy (docs/outputs.md, "Output folders") every command that writes a
folder follows (``run``, ``process``, ``diagnose``, ``experiment``, ``export``):

1. A folder is *owned* by the command that wrote it: each command leaves a
   marker ``.mixnav-output.json`` (``command``, ``complete``, ``files``).
2. ``--out`` that does not exist or is empty is used. A non-empty folder is
   reused only when its marker names the same command and it holds nothing
   but the files that command wrote; anything else (another command's
   folder, a folder with foreign files, a folder without a marker) is refused
   unless ``--overwrite``, which clears it first. ``--out`` that is a file,
   the current folder or one above it, the home folder, ``/``, or a folder
   holding the config or data files being read is refused even then.
3. ``run``, ``process``, ``diagnose`` and ``export`` write into a hidden temporary sibling
   (``.<name>.mixnav-*``) and swap it in at the end (two renames), so an
   interrupted rewrite leaves the old complete folder or the new complete one,
   never old and new files side by side; the sibling is removed on an error
   or Ctrl-C/SIGTERM, and one left by a killed run (its pid in the name) is
   removed by the next write to the same folder. When the parent folder is
   not writable the folder is rewritten in place instead: the completeness
   file (``metrics.json``) is removed first and the marker says ``complete:
   false`` until the end, so a half-written folder is never marked complete
   (and is this command's to rewrite).
4. ``experiment`` builds its folder in place (it is resumable): its marker
   says ``complete: false`` until the summaries and report are written.
5. Every file name is one path component (:func:`safe_name`): no separator,
   no ``..``, no NUL, at most 200 bytes; every file is written through
   :meth:`OutputFolder.file`, which checks that it lands inside the folder.
6. Files and folders are created with the user's umask (:mod:`mixnav.io.atomic`).
"""

from __future__ import annotations

import fnmatch
import json
import os
import re
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterable, Iterator

from ..errors import ArgumentError
from ..names import safe_name
from .atomic import atomic_write_json, default_mode, process_alive

__all__ = ["MARKER", "OutputFolder", "safe_name", "check_out_dir", "staged_output", "read_marker",
           "write_marker", "clear_folder"]

#: the marker of a folder written by mixnav
MARKER = ".mixnav-output.json"


class OutputFolder:
    """A folder being written; :meth:`file` is the only way to name a file in it."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.written: set[str] = set()

    def file(self, *parts: str) -> Path:
        """The path of ``parts`` (each checked by :func:`safe_name`) inside the folder."""
        for p in parts:
            safe_name(p)
        target = self.path.joinpath(*parts)
        root = os.path.realpath(self.path)
        if os.path.commonpath([root, os.path.realpath(target)]) != root:
            raise ArgumentError(f"refusing to write {target}: it is outside the output folder {self.path}")
        self.written.add("/".join(parts))
        return target

    def __truediv__(self, name: str) -> Path:
        return self.file(name)


def _out_error(message: str, out_dir) -> ArgumentError:
    return ArgumentError(f"{out_dir}: {message}", "--out")


def _check_path(out_dir) -> Path:
    """``out_dir`` as an absolute path, checked for what no command can write to."""
    s = os.fspath(out_dir)
    if not s or "\x00" in s:
        raise _out_error("not a usable folder name (empty or holding a NUL byte)", repr(s))
    p = Path(os.path.abspath(s))
    for part in p.parts:
        if len(part.encode("utf-8", "surrogateescape")) > 255:
            raise _out_error(f"a path component is longer than 255 bytes ({part[:20]}...)", s)
    if p.is_symlink() and p.is_dir():
        p = Path(os.path.realpath(p))   # a link to a folder: write into the folder, keep the link
    if p.exists() and not p.is_dir():
        raise _out_error("exists and is not a folder", s)
    return p


def _forbidden(p: Path, protect: Iterable = ()) -> str | None:
    """Why ``p`` may not be cleared, or None."""
    real = Path(os.path.realpath(p))
    cwd = Path(os.path.realpath(os.getcwd()))
    home = Path(os.path.realpath(os.path.expanduser("~")))
    if real == Path(real.anchor):
        return "is the root folder"
    if real == home:
        return "is your home folder"
    if real == cwd or real in cwd.parents:
        return "is the current folder or one above it"
    for q in protect:
        if q is None:
            continue
        q = Path(os.path.realpath(q))
        if q == real or real in q.parents:
            return f"holds {q}, which this command reads"
    return None


def read_marker(p: Path) -> dict | None:
    """The marker of folder ``p`` (None when absent or unreadable)."""
    try:
        doc = json.loads((Path(p) / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    return doc if isinstance(doc, dict) else None


def write_marker(p: Path, command: str, complete: bool, files: Iterable[str] = ()) -> None:
    atomic_write_json(Path(p) / MARKER, {"command": command, "complete": bool(complete),
                                         "files": sorted(set(files))})


def _contents(p: Path) -> list[str]:
    try:
        return sorted(os.listdir(p))
    except FileNotFoundError:
        return []
    except OSError as exc:
        raise _out_error(f"cannot list the folder ({exc.strerror})", p) from None


def _owned_name(name: str, marker: dict, extra_ok=()) -> bool:
    """Whether the entry ``name`` of a folder with ``marker`` was written by its command."""
    files = marker.get("files", [])
    mine = {str(f).split("/")[0] for f in files if isinstance(f, str)} | {MARKER}
    return (name in mine or any(fnmatch.fnmatchcase(name, pat) for pat in extra_ok)
            or name.startswith(".") and name.endswith(".tmp"))


def _owned(p: Path, command: str, marker: dict | None, extra_ok=()) -> bool:
    """Whether non-empty ``p`` is ``command``'s folder holding only its own files."""
    if marker is None or marker.get("command") != command or not isinstance(marker.get("files", []), list):
        return False
    if marker.get("complete") is False and command != "experiment":
        return True   # this command's half-written folder (rewritten in place, interrupted)
    return all(_owned_name(n, marker, extra_ok) for n in _contents(p))


def clear_folder(p: Path) -> None:
    """Empty folder ``p`` (the marker first, so a cleared-half folder is never marked)."""
    (p / MARKER).unlink(missing_ok=True)
    for name in _contents(p):
        q = p / name
        if q.is_dir() and not q.is_symlink():
            shutil.rmtree(q)
        else:
            q.unlink()


def check_out_dir(out_dir, command: str, overwrite: bool = False, protect: Iterable = (),
                  resume: bool = False, extra_ok=()) -> tuple[Path, str]:
    """Apply the policy to ``out_dir`` before anything is computed.

    Returns ``(path, state)``, ``state`` one of ``"new"`` (missing or empty),
    ``"same"`` (this command's own folder: to be replaced, or resumed) and
    ``"clear"`` (to be cleared: ``overwrite`` was given). Raises an
    ArgumentError naming ``--out`` otherwise.
    """
    p = _check_path(out_dir)
    contents = _contents(p) if p.is_dir() else []
    if not contents:
        return p, "new"
    marker = read_marker(p)
    legacy = command == "experiment" and marker is None and (p / "manifest.json").exists()
    same = legacy or _owned(p, command, marker, extra_ok)
    if overwrite:
        why = _forbidden(p, protect)
        if why:
            raise _out_error(f"refusing to clear this folder: it {why}; choose another --out", p)
        return p, "clear"
    if same:
        return p, "same"
    shown = contents
    if marker is not None and marker.get("command") != command:
        what = f"the output of 'mixnav {marker.get('command')}'"
    elif marker is not None:
        what = f"'mixnav {command}' output plus files it did not write"
        shown = [n for n in contents if not _owned_name(n, marker, extra_ok)]
    else:
        what = "files not written by mixnav"
    raise _out_error(f"folder is not empty: it holds {what} ({', '.join(shown[:4])}"
                     f"{', ...' if len(shown) > 4 else ''}); choose an empty or new folder, or "
                     "pass --overwrite to clear it first", p)


def _remove_stale_siblings(p: Path) -> None:
    """Remove the temporary siblings of ``p`` left by a run that was killed (``kill -9``):
    ``.<name>.mixnav-<pid>-*`` and ``.<name>.old-<pid>-*`` whose process no longer runs."""
    pat = re.compile(rf"^\.{re.escape(p.name[:100])}\.(?:mixnav|old)-(\d+)-")
    try:
        names = os.listdir(p.parent)
    except OSError:
        return
    for n in names:
        m = pat.match(n)
        if m and not process_alive(int(m.group(1))):
            shutil.rmtree(p.parent / n, ignore_errors=True)


def _make_dir(p: Path) -> None:
    p.mkdir(parents=True, exist_ok=True)


@contextmanager
def staged_output(out_dir, command: str, overwrite: bool = False, protect: Iterable = (),
                  complete_file: str = "metrics.json") -> Iterator[OutputFolder]:
    """Write a command's folder as a whole: yields an :class:`OutputFolder` to write into.

    See the module docstring (rules 2 and 3). On success the marker is
    written and the folder swapped in; on any error (also Ctrl-C) the
    temporary folder is removed and ``out_dir`` is as it was.
    """
    p, state = check_out_dir(out_dir, command, overwrite, protect)
    parent = p.parent
    try:
        _make_dir(parent)
    except OSError as exc:
        raise _out_error(f"cannot create the parent folder ({exc.strerror})", p) from None
    _remove_stale_siblings(p)
    try:
        tmp = Path(tempfile.mkdtemp(dir=parent, prefix=f".{p.name[:100]}.mixnav-{os.getpid()}-"))
    except OSError:
        tmp = None
    if tmp is not None and _forbidden(p) is not None:
        os.rmdir(tmp)  # the current folder (or above): never renamed away under the user
        tmp = None
    if tmp is None:  # parent not writable: rewrite in place, marker and completeness file first
        try:
            _make_dir(p)
            if state in ("same", "clear"):
                (p / complete_file).unlink(missing_ok=True)
                clear_folder(p)
            write_marker(p, command, False)   # a half-written folder of this command, never complete
        except OSError as exc:
            raise _out_error(f"cannot write here ({exc.strerror})", p) from None
        folder = OutputFolder(p)
        yield folder
        write_marker(p, command, True, _contents(p))
        return
    os.chmod(tmp, default_mode(0o777))
    folder = OutputFolder(tmp)
    try:
        yield folder
        write_marker(tmp, command, True, _contents(tmp))
        if p.exists():
            old = Path(tempfile.mkdtemp(dir=parent, prefix=f".{p.name[:100]}.old-{os.getpid()}-"))
            os.rename(p, old / "x")
            try:
                os.rename(tmp, p)
            except BaseException:
                os.rename(old / "x", p)
                raise
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(tmp, p)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
