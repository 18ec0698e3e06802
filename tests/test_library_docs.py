"""docs/library.md runs: every ```python block, in order, in one namespace.

Blocks marked ``# needs: shared-data`` are skipped when ../shared/data is absent.
The examples carry their own asserts (accuracy bounds a broken filter misses).
"""

import re
from pathlib import Path

import pytest

DOC = Path(__file__).resolve().parents[1] / "docs" / "library.md"
from .conftest import DATA_DIR as SHARED  # MIXNAV_DATA or ../shared/data


def test_library_doc_examples_run(tmp_path, monkeypatch, capsys):
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)
    assert len(blocks) >= 6
    monkeypatch.chdir(tmp_path)
    ns = {"__name__": "library_doc"}
    ran = 0
    for i, code in enumerate(blocks):
        if "# needs: shared-data" in code and not SHARED.is_dir():
            continue
        try:
            exec(compile(code, f"{DOC.name}[block {i}]", "exec"), ns)
        except Exception as exc:  # say which block failed
            pytest.fail(f"docs/library.md block {i} failed: {type(exc).__name__}: {exc}\n{code}")
        ran += 1
    assert ran >= len(blocks) - 1
    assert "horizontal RMSE" in capsys.readouterr().out
