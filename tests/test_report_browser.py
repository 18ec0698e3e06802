"""The experiment report opened in a real headless browser (Debian's chromium).

Skips when chromium is not installed (``.ci/run`` installs it when it can).
"""

import functools
import html
import http.server
import json
import os
import re
import shutil
import subprocess
import tarfile
import threading

import numpy as np
import pandas as pd
import pytest
from matplotlib.image import imread

from mixnav.experiment.montecarlo import run_experiment, write_experiment_outputs
from mixnav.experiment.report import write_report
from mixnav.experiment.webmap import map_html

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


# --- the report's interactive map (mixnav.experiment.webmap) -------------------------------
# The page loads Leaflet from a CDN, which this sandbox cannot reach: the test serves the same
# Leaflet release (npm's package, or MIXNAV_LEAFLET_DIST naming its dist folder) on localhost
# and points the page there. The tiles stay unreachable: the map's background is blank.

LEAFLET_CDN = re.compile(r"https://cdn\.jsdelivr\.net/npm/leaflet@([0-9.]+)/dist/")
CHECK = """<script>
(function () {
  var errors = [];
  window.addEventListener('error', function (e) { errors.push(String(e.message)); });
  window.addEventListener('load', function () { setTimeout(function () {
    var m = Object.keys(window).filter(function (k) { return k.indexOf('map_') === 0; })
                               .map(function (k) { return window[k]; })[0];
    var out = {errors: errors, lines: 0, points: 0, in_view: 0, markers: 0};
    m.eachLayer(function (l) {
      if (l instanceof L.Polyline) {
        out.lines += 1; out.points += l.getLatLngs().length;
        if (m.getBounds().contains(l.getBounds())) out.in_view += 1;
      } else if (l instanceof L.CircleMarker) { out.markers += 1; }
    });
    out.zoom = m.getZoom();
    document.body.setAttribute('data-check', JSON.stringify(out));
  }, 100); });
})();
</script>"""


@pytest.fixture(scope="module")
def leaflet(tmp_path_factory):
    """A localhost URL serving Leaflet's dist folder; skips when none can be had."""
    dist = os.environ.get("MIXNAV_LEAFLET_DIST")
    if not dist:
        npm = shutil.which("npm")
        if npm is None:
            pytest.skip("no Leaflet: npm is not installed and MIXNAV_LEAFLET_DIST is not set")
        folder = tmp_path_factory.mktemp("leaflet")
        version = LEAFLET_CDN.search(map_html({"x": _track(10)})).group(1)
        try:
            subprocess.run([npm, "pack", f"leaflet@{version}", "--silent"], cwd=folder, capture_output=True,
                           timeout=120, check=True)
            with tarfile.open(next(folder.glob("leaflet-*.tgz"))) as tar:
                tar.extractall(folder, filter="data")
        except (subprocess.SubprocessError, OSError, StopIteration, tarfile.TarError) as e:
            pytest.skip(f"no Leaflet: npm pack failed ({e})")
        dist = folder / "package" / "dist"
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(dist))
    handler.log_message = lambda *a: None
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_address[1]}/"
    server.shutdown()


def _track(n, dt=0.1, shift=0.0):
    t = np.arange(n) * dt
    return pd.DataFrame({"time_s": t, "lat_deg": 39.9 + 2e-6 * t + 2e-5 * np.sin(t / 30) + shift,
                         "lon_deg": -105.1 + 3e-6 * t, "height_m": np.zeros(n)})


@pytest.fixture(scope="module")
def map_report(tmp_path_factory, leaflet):
    out = tmp_path_factory.mktemp("map")
    sols = {"ekf": _track(20000), "ukf": _track(20000, shift=3e-5)}
    page = map_html(sols, _track(4000, 0.5), _track(2000, 1.0), [(300.0, 360.0)], title="map test")
    write_report(out, "map test", {"methods": {}}, {}, web_map=page)   # no figures: colour is the map's
    for name in ("map.html", "report.html"):
        text = LEAFLET_CDN.sub(leaflet, (out / name).read_text())
        (out / f"local_{name}").write_text(text.replace("</body>", CHECK + "</body>", 1) if name == "map.html"
                                           else text)
    return out


def test_browser_draws_the_map_without_a_script_error(map_report, tmp_path):
    dom = _chromium(tmp_path, "--virtual-time-budget=5000", "--dump-dom",
                    (map_report / "local_map.html").as_uri()).stdout.decode()
    found = re.search(r'data-check="([^"]*)"', dom)
    assert found, "the check script did not run (Leaflet not loaded?)"
    check = json.loads(html.unescape(found.group(1)))
    assert check["errors"] == []
    # reference, two methods, and the window's span on each of the three
    assert check["lines"] == 6 and check["in_view"] == 6, check
    assert check["points"] > 3 * 2000 and check["markers"] == 2000 and check["zoom"] > 10


def test_browser_shows_the_map_inside_the_report(map_report, tmp_path):
    shot = tmp_path / "shot.png"
    _chromium(tmp_path, "--window-size=1100,1000", "--virtual-time-budget=5000", f"--screenshot={shot}",
              (map_report / "local_report.html").as_uri())
    img = imread(shot)[..., :3]
    coloured = (img.max(axis=2) - img.min(axis=2)) > 0.3
    # the tracks (blue, orange) drawn inside the iframe: the page has no figure of its own
    assert coloured.mean() > 1e-3, f"only {coloured.mean():.2e} of the page is coloured"
    orange = (img[..., 0] > 0.9) & (img[..., 1] > 0.5) & (img[..., 1] < 0.8) & (img[..., 2] < 0.5)
    assert orange.sum() > 100
