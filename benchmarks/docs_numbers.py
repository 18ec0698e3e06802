"""Numbers in the docs, filled from the results files (none typed by hand).

    python benchmarks/docs_numbers.py            # check: exit 1 and list every number that differs
    python benchmarks/docs_numbers.py --write    # rewrite the numbers from the results files

A measured number in a doc is written with the place it comes from, in an HTML comment
that markdown does not show::

    the causal filter's RMSE is <!--r smartloc.json|causal/epoch-mixture/rmse_m|.2f-->6.59<!--/r--> m

``FILE|PATH|FORMAT``:

- ``FILE``: a file under ``benchmarks/results/`` (or ``benchmarks/reproductions/``), made by
  a benchmark script (the results file names the script);
- ``PATH``: for a ``.json`` file, keys (and list indices) separated by ``/``; for a ``.md``
  file, ``ROW/COLUMN``: the table row whose first cell equals ``ROW`` (after stripping
  spaces and ``**``), and the column whose header equals ``COLUMN`` (or a 0-based
  column number). Keys that hold ``/`` or ``|`` cannot be addressed: the file's
  JSON should not use them;
- ``FORMAT``: a Python format spec (``.2f``, ``.0f``, ``d``, ``.3g``), optionally followed by
  ``*K`` to scale first (``.0f*100`` writes a share as a percentage); for a ``.md`` cell
  the cell's text is used as it is when ``FORMAT`` is ``s``.

Inside a markdown table, write ``\\|`` for each ``|`` of the marker (a bare one would split the
cell): ``<!--r smartloc.json\\|causal/epoch-mixture/rmse_m\\|.2f-->6.59<!--/r-->``.

A doc that cites one file many times names it once, anywhere in the doc:
``<!--r-def sl tune_smartloc.json|against_reference-->``; then ``<!--r @sl/shipped/worst_own_m|.1f-->``
stands for ``<!--r tune_smartloc.json|against_reference/shipped/worst_own_m|.1f-->``.

tests/test_docs_numbers.py fails when a doc's number differs from its file, or a marker
points at nothing; ``--write`` after a benchmark rewrote its results file. The README's
headline table (``readme_results.py``) and docs/tuning.md's table (``tune_drive0708.py``)
are blocks of their own, checked by tests/test_readme.py.
"""

from __future__ import annotations

import json
import re
import sys
from functools import lru_cache
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
#: where a marker's FILE is looked up, in this order
RESULT_DIRS = (HERE / "results", HERE / "reproductions")
#: the docs whose numbers are checked
DOCS = (ROOT / "README.md", ROOT / "ARCHITECTURE.md", *sorted((ROOT / "docs").glob("*.md")))

MARKER = re.compile(r"<!--r (?P<spec>[^>]*?)-->(?P<value>.*?)<!--/r-->", re.S)
ALIAS = re.compile(r"<!--r-def (?P<name>\w+) (?P<file>[^|>]+)\|(?P<prefix>[^>]*?)-->")


class MarkerError(ValueError):
    """A marker that cannot be resolved; the message names the doc and line."""


def _results_file(name: str) -> Path:
    for d in RESULT_DIRS:
        if (d / name).is_file():
            return d / name
    raise FileNotFoundError(f"no results file '{name}' under {', '.join(_shown(d) for d in RESULT_DIRS)}")


def _shown(path: Path) -> str:
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


@lru_cache(maxsize=None)
def _load_json(path: Path):
    return json.loads(path.read_text())


@lru_cache(maxsize=None)
def _md_tables(path: Path) -> list[list[list[str]]]:
    """The markdown tables of ``path``: each a list of rows (the header first, the rule dropped)."""
    tables, cur = [], []
    for line in path.read_text().splitlines():
        s = line.strip()
        if s.startswith("|"):
            cells = [c.strip() for c in s.strip("|").split("|")]
            if not all(re.fullmatch(r":?-+:?", c) for c in cells if c):
                cur.append(cells)
        elif cur:
            tables.append(cur)
            cur = []
    if cur:
        tables.append(cur)
    return tables


def _plain(cell: str) -> str:
    return cell.replace("**", "").replace("`", "").strip()


def _md_value(path: Path, where: str) -> str:
    row, sep, col = where.rpartition("/")
    if not sep:
        raise KeyError(f"a .md path is ROW/COLUMN, got '{where}'")
    for table in _md_tables(path):
        header = [_plain(c) for c in table[0]]
        if col.isdigit():
            j = int(col)
        elif col in header:
            j = header.index(col)
        else:
            continue
        for cells in table[1:]:
            if _plain(cells[0]) == row and j < len(cells):
                return cells[j]
    raise KeyError(f"no table row '{row}' with a column '{col}'")


def _json_value(path: Path, where: str):
    v = _load_json(path)
    for part in where.split("/"):
        if isinstance(v, list):
            v = v[int(part)]
        elif isinstance(v, dict) and part in v:
            v = v[part]
        else:
            raise KeyError(f"no key '{part}' (of '{where}')")
    return v


def render(spec: str) -> str:
    """The text of one marker ``FILE|PATH|FORMAT``, from its results file."""
    try:   # "\|" in a marker inside a markdown table cell, where a bare "|" would split the cell
        name, where, fmt = (s.strip() for s in spec.replace("\\|", "|").split("|"))
    except ValueError:
        raise MarkerError(f"a marker is 'FILE|PATH|FORMAT', got '{spec}'") from None
    fmt, _, scale = fmt.partition("*")
    path = _results_file(name)
    if path.suffix == ".md":
        cell = _md_value(path, where)
        if fmt == "s":
            return cell
        try:
            value = float(re.sub(r"[^0-9eE+\-.]", "", cell))
        except ValueError:
            raise KeyError(f"cell '{cell}' is not a number (use format 's')") from None
    else:
        value = _json_value(path, where)
    if scale:
        value = value * float(scale)
    return format(value, fmt)


def markers(text: str):
    """``(line, spec, written value, match)`` for each marker of ``text``."""
    for m in MARKER.finditer(text):
        yield text.count("\n", 0, m.start()) + 1, m.group("spec"), m.group("value"), m


def _expand(spec: str, aliases: dict[str, tuple[str, str]]) -> str:
    """``@name/PATH|FORMAT`` -> ``FILE|PREFIX/PATH|FORMAT`` (a ``<!--r-def -->`` of the doc)."""
    if not spec.startswith("@"):
        return spec
    head, _, fmt = spec[1:].partition("|")
    name, _, rest = head.partition("/")
    if name not in aliases:
        raise KeyError(f"no '<!--r-def {name} FILE|PREFIX-->' in this doc")
    file, prefix = aliases[name]
    return f"{file}|{'/'.join(p for p in (prefix, rest) if p)}|{fmt}"


def fill(text: str, doc: str = "<text>") -> tuple[str, list[str]]:
    """``text`` with every marker's value rendered from its file, and the list of values that
    differed (``doc:line: spec: written -> from the file``). A marker that resolves to
    nothing raises :class:`MarkerError` naming ``doc`` and the line."""
    aliases = {m.group("name"): (m.group("file").strip(), m.group("prefix").strip()) for m in ALIAS.finditer(text)}
    diffs, out, last = [], [], 0
    for line, spec, written, m in markers(text):
        try:
            value = render(_expand(spec, aliases))
        except (FileNotFoundError, KeyError, IndexError, ValueError, TypeError) as e:
            raise MarkerError(f"{doc}:{line}: marker '{spec}': {e}") from None
        if value != written:
            diffs.append(f"{doc}:{line}: {spec}: {written!r} -> {value!r}")
        out += [text[last:m.start("value")], value]
        last = m.end("value")
    out.append(text[last:])
    return "".join(out), diffs


def check(docs=DOCS, write: bool = False) -> list[str]:
    """Every differing number of ``docs`` (written back when ``write``)."""
    diffs = []
    for path in docs:
        text = path.read_text()
        new, d = fill(text, str(path.relative_to(ROOT)))
        diffs += d
        if write and new != text:
            path.write_text(new)
    return diffs


def main(argv) -> int:
    diffs = check(write="--write" in argv)
    for d in diffs:
        print(d)
    if diffs and "--write" not in argv:
        print(f"{len(diffs)} numbers differ from their results files: rerun with --write", file=sys.stderr)
        return 1
    n = sum(len(list(markers(p.read_text()))) for p in DOCS)
    print(f"{n} numbers in {len(DOCS)} docs, {'rewritten' if diffs else 'all as in their results files'}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
