"""The experiment report opened in a real headless browser (Debian's chromium).

Skips when chromium is not installed (``.ci/run`` installs it when it can).
"""

import shutil
import subprocess

import pytest
from matplotlib.image import imread

from mixnav.experiment.montecarlo import run_experiment, write_experiment_outputs

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed")

# The flags a root process in this sandbox needs; the network stays closed.
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def _chromium(tmp_path, *args) -> subprocess.CompletedProcess:
    return subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={tmp_path / 'profile'}", *args],
                          capture_output=True, timeout=120, check=True)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("exp")
    df = run_experiment("loose-demo", 2, out, workers=1, progress=False)
    write_experiment_outputs("loose-demo", df, out)
    return out / "report.html"


def test_browser_parses_tables_and_embedded_figures(report, tmp_path):
    dom = _chromium(tmp_path, "--dump-dom", report.as_uri()).stdout.decode()
    assert dom.count("<table") >= 2  # means with CIs, consistency
    assert "Means over runs" in dom and "Monte Carlo consistency" in dom
    n_img = dom.count("<img")
    assert n_img == dom.count("src=\"data:image/png;base64,")  # every figure embedded
    assert n_img >= 5  # box plots, three RMS error figures, NEES, NIS


def test_browser_renders_the_figures(report, tmp_path):
    shot = tmp_path / "shot.png"
    _chromium(tmp_path, "--window-size=1200,6000", f"--screenshot={shot}", report.as_uri())
    img = imread(shot)[..., :3]
    # Tables and text are grey; only decoded figures put colour (the method's
    # blue line, the green mean markers, orange medians) on the page.
    coloured = (img.max(axis=2) - img.min(axis=2)) > 0.3
    assert coloured.mean() > 1e-3, f"only {coloured.mean():.2e} of the page is coloured"
    # and the figures sit below the tables: nothing coloured in the top 150 px
    assert coloured[:150].mean() < 1e-4
