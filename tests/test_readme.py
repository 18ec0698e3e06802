"""The README's headline table is what benchmarks/readme_results.py builds from the results
files (no number copied by hand), and every relative link of the README and of
docs/features.md (moved out of it) points at a file that exists."""

import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import readme_results  # noqa: E402


def test_the_headline_table_is_built_from_the_results_files():
    block = readme_results.readme_block((ROOT / "README.md").read_text())
    assert block == readme_results.table(), "rerun: python benchmarks/readme_results.py --write"


def test_a_changed_result_changes_the_table(monkeypatch):
    """The check is not vacuous: a results file read with another number gives another table."""
    real = readme_results._json

    def bumped(name):
        d = real(name)
        if name == "outage_sweep_drive0708.json":
            d["summary"]["aided"]["worst_horizontal_max_m"] += 1.0
        return d
    monkeypatch.setattr(readme_results, "_json", bumped)
    assert readme_results.table() != readme_results.readme_block((ROOT / "README.md").read_text())


def test_the_tuning_table_is_built_from_the_results_file():
    import json
    import tune_drive0708
    res = json.loads((ROOT / "benchmarks" / "results" / "tune_drive0708.json").read_text())
    block = tune_drive0708.docs_block((ROOT / "docs" / "tuning.md").read_text())
    assert block == tune_drive0708.docs_table(res), "rerun: python benchmarks/tune_drive0708.py --write-docs"
    res["folds"]["tuned-on-first"]["tuned"]["median_m"] += 1.0      # not vacuous
    assert tune_drive0708.docs_table(res) != block


@pytest.mark.parametrize("doc", ["README.md", "docs/features.md", "docs/evaluation.md", "docs/tuning.md"])
def test_relative_links_resolve(doc):
    path = ROOT / doc
    missing = []
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", path.read_text()):
        if target.startswith(("http://", "https://", "mailto:")):
            continue
        if not (path.parent / target).exists():
            missing.append(target)
    assert not missing, f"{doc}: links to missing files: {missing}"
