"""Every marked number in the README, ARCHITECTURE.md and docs/ is the one its results file
holds (benchmarks/docs_numbers.py), and the check is not vacuous."""

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import docs_numbers  # noqa: E402


def test_every_marked_number_is_its_results_files():
    diffs = docs_numbers.check()
    assert not diffs, "rerun: python benchmarks/docs_numbers.py --write\n" + "\n".join(diffs[:40])


@pytest.fixture
def results(tmp_path, monkeypatch):
    """A results folder of our own: one JSON and one markdown file."""
    (tmp_path / "r.json").write_text(json.dumps({"a": {"rmse_m": 6.5949, "runs": [1.0, 2.25]}, "share": 0.571}))
    (tmp_path / "t.md").write_text("# t\n\n| method | h RMSE | max |\n|---|---:|---:|\n"
                                   "| **ekf** | 24.55 | 52.3 m |\n| mixture | 6.59 | 11.2 m |\n")
    monkeypatch.setattr(docs_numbers, "RESULT_DIRS", (tmp_path,))
    docs_numbers._load_json.cache_clear()
    docs_numbers._md_tables.cache_clear()
    yield tmp_path
    docs_numbers._load_json.cache_clear()
    docs_numbers._md_tables.cache_clear()


def test_values_are_rendered_from_json_and_markdown_tables(results):
    assert docs_numbers.render("r.json|a/rmse_m|.2f") == "6.59"
    assert docs_numbers.render("r.json|a/runs/1|.1f") == "2.2"       # list index; round half to even
    assert docs_numbers.render("r.json|share|.0f*100") == "57"         # scaled to a percentage
    assert docs_numbers.render("t.md|ekf/h RMSE|.1f") == "24.6"         # '**' stripped from the row name
    assert docs_numbers.render("t.md|mixture/max|s") == "11.2 m"       # the cell as written
    assert docs_numbers.render("t.md|mixture/2|.0f") == "11"           # a column by number


def test_a_wrong_number_is_found_and_rewritten(results):
    text = "RMSE <!--r r.json|a/rmse_m|.2f-->6.40<!--/r--> m and <!--r t.md|ekf/max|s-->52.3 m<!--/r-->"
    new, diffs = docs_numbers.fill(text, "doc.md")
    assert diffs == ["doc.md:1: r.json|a/rmse_m|.2f: '6.40' -> '6.59'"]
    assert new == text.replace("6.40", "6.59")
    assert docs_numbers.fill(new, "doc.md") == (new, [])                # written once, stable


def test_a_marker_in_a_table_cell_escapes_its_bars(results):
    text = "| ekf | <!--r r.json\\|a/rmse_m\\|.2f-->0<!--/r--> m |"
    new, diffs = docs_numbers.fill(text, "doc.md")
    assert new == text.replace("-->0<", "-->6.59<") and len(diffs) == 1


def test_a_doc_names_its_file_once(results):
    text = "<!--r-def a r.json|a-->\nRMSE <!--r @a/rmse_m|.2f-->0<!--/r--> and <!--r @a/runs/0|.0f-->1<!--/r-->"
    new, diffs = docs_numbers.fill(text, "doc.md")
    assert new.endswith("RMSE <!--r @a/rmse_m|.2f-->6.59<!--/r--> and <!--r @a/runs/0|.0f-->1<!--/r-->")
    assert len(diffs) == 1
    with pytest.raises(docs_numbers.MarkerError, match="doc.md:1: .*no '<!--r-def b"):
        docs_numbers.fill("<!--r @b/rmse_m|.2f-->0<!--/r-->", "doc.md")


@pytest.mark.parametrize("spec, says", [
    ("nothere.json|a|.2f", "no results file 'nothere.json'"),
    ("r.json|a/nokey|.2f", "no key 'nokey'"),
    ("t.md|lstm/h RMSE|.2f", "no table row 'lstm'"),
    ("r.json|a/rmse_m", "FILE|PATH|FORMAT"),
])
def test_a_marker_pointing_at_nothing_names_the_doc_and_line(results, spec, says):
    with pytest.raises(docs_numbers.MarkerError, match="doc.md:2: ") as e:
        docs_numbers.fill(f"first line\nvalue <!--r {spec}-->1.0<!--/r-->", "doc.md")
    assert says in str(e.value)
