"""The report's interactive map (mixnav.experiment.webmap): what it draws, how the report
holds it, and that writing it needs no network."""

import html
import json
import re
import socket

import numpy as np
import pandas as pd
import pytest
from matplotlib.patches import Rectangle, Polygon

from mixnav.experiment import figures
from mixnav.experiment.report import write_report
from mixnav.experiment.webmap import DECIMALS, POINT_NAME, decimation_index, map_html, map_layers

from .test_report import OUTAGES, synthetic_solution


def polylines(page: str) -> list[np.ndarray]:
    """The coordinates of every ``L.polyline`` in a folium page, (K, 2) [deg] each."""
    found = re.findall(r"L\.polyline\(\s*(\[\[.*?\]\])\s*,", page, flags=re.S)
    return [np.array(json.loads(s)) for s in found]


def long_solution(n=20000, dt=0.1) -> pd.DataFrame:
    t = np.arange(n) * dt
    return pd.DataFrame({"time_s": t, "lat_deg": 39.9 + 1e-6 * t + 1e-5 * np.sin(t / 30),
                         "lon_deg": -105.1 + 2e-6 * t, "height_m": np.zeros(n)})


def test_decimation_keeps_ends_and_window_edges():
    t = np.arange(20000) * 0.1
    k = decimation_index(t, 3000, [(123.45, 456.78)])
    assert len(k) <= 3000 + 3 and k[0] == 0 and k[-1] == len(t) - 1
    inside = np.flatnonzero((t >= 123.45) & (t <= 456.78))
    assert inside[0] in k and inside[-1] in k
    assert np.array_equal(decimation_index(t[:50], 3000), np.arange(50))


def test_map_coordinates_are_the_solutions():
    sols = {"ekf": long_solution(), "ukf<x>": long_solution().assign(lat_deg=lambda d: d.lat_deg + 1e-4)}
    sols["ekf"].loc[5, "lat_deg"] = np.nan   # a row without a position is left out
    ref = long_solution(4000, 0.5)
    gnss = long_solution(2000, 1.0)
    outages = [(300.0, 360.0), (1200.0, 1260.0)]
    layers = map_layers(sols, ref, gnss, outages)
    assert [t.name for t in layers.tracks] == ["reference", "ekf", "ukf<x>"]
    page = map_html(sols, ref, gnss, outages)
    lines = polylines(page)
    tracks = [ln for ln in lines if len(ln) > 1000]
    assert len(tracks) == 3 and all(len(ln) <= 3003 for ln in tracks)
    for line, (name, df) in zip(tracks[1:], sols.items()):
        df = df.dropna()
        k = decimation_index(df.time_s.to_numpy(), 3000, outages)
        want = df[["lat_deg", "lon_deg"]].to_numpy()[k]
        assert line.shape == want.shape
        np.testing.assert_allclose(line, want, rtol=0, atol=0.6 * 10.0 ** -DECIMALS)
    # the GNSS fixes: one GeoJSON MultiPoint, lon/lat
    pts = np.array(json.loads(re.search(r'"coordinates": (\[\[.*?\]\]), "type": "MultiPoint"', page).group(1)))
    np.testing.assert_allclose(pts[:, ::-1], gnss[["lat_deg", "lon_deg"]].to_numpy(), atol=1e-7)
    # names are escaped, the tiles and Leaflet are the page's only external resources
    assert "ukf&lt;x&gt;" in page and "ukf<x>" not in page
    hosts = set(re.findall(r"https?://([^/\"' ]+)", page))
    assert hosts <= {"cdn.jsdelivr.net", "tile.openstreetmap.org", "www.openstreetmap.org"}, hosts


def test_highlighted_spans_are_the_outage_windows():
    sols = {"ekf": long_solution()}
    ref = long_solution(4000, 0.5)
    outages = [(300.0, 360.0), (1200.0, 1260.0), (5000.0, 5100.0)]   # the last after the run
    layers = map_layers(sols, ref, None, outages)
    for tr, df in zip(layers.tracks, (ref, sols["ekf"])):
        assert [(a, b) for a, b, _, _ in tr.spans] == outages[:2]
        for a, b, t, ll in tr.spans:
            inside = df[(df.time_s >= a) & (df.time_s <= b)]
            assert t[0] == inside.time_s.iloc[0] and t[-1] == inside.time_s.iloc[-1]
            assert np.all((t >= a) & (t <= b))
            sel = df.set_index("time_s").loc[t, ["lat_deg", "lon_deg"]].to_numpy()
            np.testing.assert_allclose(ll, sel, atol=0.6 * 10.0 ** -DECIMALS)
    page = map_html(sols, ref, None, outages)
    for name in ("reference", "ekf"):
        for a, b in outages[:2]:
            assert f"{name}: GNSS outage {a:g} - {b:g} s" in page
    spans = [ln for ln in polylines(page) if len(ln) < 1000]
    assert len(spans) == 4     # two windows on two tracks


def surveyed_points(page: str) -> list[tuple[list[float], str]]:
    """``([lat, lon], popup text)`` of every circle marker with a Leaflet popup in a folium page."""
    found = re.findall(r"var (circle_marker_\w+) = L\.circleMarker\(\s*(\[[^\]]*\])", page)
    out = []
    for name, where in found:
        popup = re.search(re.escape(name) + r'\.bindPopup\(("(?:[^"\\]|\\.)*")', page)
        if popup:
            out.append((json.loads(where), json.loads(popup.group(1))))
    return out


def test_a_static_receivers_surveyed_point_is_a_marker_with_its_coordinates():
    # fixes scattered 10-20 m around a point (a static receiver): the point is not one of them
    rng = np.random.default_rng(3)
    fixes = pd.DataFrame({"time_s": np.arange(200.0), "lat_deg": 22.3 + 1e-4 * rng.standard_normal(200),
                          "lon_deg": 114.18 + 1e-4 * rng.standard_normal(200), "height_m": np.zeros(200)})
    point = (22.30431234567, 114.18512345678, 3.25)      # ~500 m north-east: widens the view
    layers = map_layers({"spp": fixes}, reference_point=point)
    assert layers.point == (22.3043123, 114.1851235, 3.25)
    (south, west), (north, east) = layers.bounds()
    assert north == 22.3043123 and east == 114.1851235 and south < 22.3 and west < 114.18
    page = map_html({"spp": fixes}, reference_point=point)
    (where, text), = surveyed_points(page)
    assert where == [22.3043123, 114.1851235]
    assert text == f"{POINT_NAME}: latitude 22.3043123 deg, longitude 114.1851235 deg, height 3.250 m"
    assert re.search(re.escape(f'"{POINT_NAME}" : feature_group_'), page)   # its own layer in the control
    # without it, no marker; a point alone is still a map
    assert surveyed_points(map_html({"spp": fixes})) == []
    alone = map_html({}, reference_point=point)
    assert alone is not None and len(surveyed_points(alone)) == 1
    with pytest.raises(ValueError, match="reference_point must be finite"):
        map_layers({"spp": fixes}, reference_point=(np.nan, 114.0, 0.0))


def test_nothing_to_draw_gives_no_map():
    empty = long_solution(3).assign(lat_deg=np.nan)
    assert map_html({"spp": empty}) is None


def test_report_embeds_the_map_written_beside_it_without_network(tmp_path, monkeypatch):
    def refuse(*a, **k):
        raise OSError("no network in this test")
    monkeypatch.setattr(socket.socket, "connect", refuse)
    monkeypatch.setattr(socket, "getaddrinfo", refuse)
    monkeypatch.setattr(socket, "create_connection", refuse)

    sols = {"ekf": synthetic_solution(1.0, True), "gmm": synthetic_solution(2.0, False)}
    ref = sols["ekf"][["time_s", "lat_deg", "lon_deg"]]
    figs = {"trajectory": figures.trajectory_figure(sols, ref, ref.iloc[::5], OUTAGES)}
    page_map = map_html(sols, ref, ref.iloc[::5], OUTAGES, title="t <1>")
    path = write_report(tmp_path, "t <1>", {"methods": {}}, figs, web_map=page_map)
    assert (tmp_path / "map.html").read_text() == page_map
    assert "<title>t &lt;1&gt;</title>" in page_map
    page = path.read_text()
    # inlined whole (the report stays one file) and linked; the PNG plan view stays
    srcdoc = re.search(r"<iframe title='map' sandbox='allow-scripts' srcdoc='([^']*)'></iframe>", page)
    assert srcdoc and html.unescape(srcdoc.group(1)) == page_map
    assert "href='map.html'" in page and (tmp_path / "trajectory.png").exists()
    # the report's own page runs nothing: every script is inside the escaped srcdoc
    assert "<script" not in page.lower()
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_report_without_map_is_unchanged(tmp_path):
    page = write_report(tmp_path, "x", {"methods": {}}, {}).read_text()
    assert "<iframe" not in page and not (tmp_path / "map.html").exists()


@pytest.mark.parametrize("kind", ["horizontal", "position"])
def test_error_figures_shade_the_outage_windows(kind):
    sols = {"ekf": synthetic_solution(1.0, True)}
    fig = (figures.horizontal_error_figure(sols, OUTAGES) if kind == "horizontal"
           else figures.error_figure(sols, "position", OUTAGES))
    for ax in fig.axes:
        spans = [p for p in ax.patches if isinstance(p, (Rectangle, Polygon))]
        xs = [sorted({round(float(x), 9) for x in p.get_xy()[:, 0]}) if isinstance(p, Polygon)
              else [p.get_x(), p.get_x() + p.get_width()] for p in spans]
        assert [[a, b] for a, b in OUTAGES] == [[x[0], x[-1]] for x in xs]
