"""An interactive map of the trajectories (folium, i.e. Leaflet): ``map.html`` of a report.

Each method's track, the reference (a trajectory, or a static receiver's surveyed point:
a marker whose popup gives its coordinates) and the GNSS fixes on OpenStreetMap tiles, the
stretches inside the GNSS outage (withheld) windows highlighted on each track, and a layer
control to switch each on or off. The page loads Leaflet and the tiles from the web when it
is viewed; nothing is fetched when it is written, and a viewer offline sees an empty map
(the report's ``trajectory.png`` is the offline plan view).

:func:`map_layers` builds what is drawn (plain arrays, tested on their own);
:func:`map_html` renders it. Tracks are decimated to at most ``max_points`` points each
(every k-th sample, plus the first and last sample and those at each window's ends), the
coordinates rounded to 7 decimals (1 cm).
"""

from __future__ import annotations

import html
import json
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

__all__ = ["MapLayers", "map_html", "map_layers"]

#: points kept of each track, each highlighted span and the GNSS fixes
MAX_POINTS = 3000
#: decimals of the coordinates [deg]: 1e-7 deg is 1.1 cm
DECIMALS = 7
_OUTAGE_COLOUR = "#ff8c00"
_REFERENCE_COLOUR = "#000000"
_GNSS_COLOUR = "#7f7f7f"
#: the popup's and the layer's name for a static receiver's surveyed point
POINT_NAME = "surveyed point ([reference_point])"


@dataclass
class Track:
    """One line on the map: ``time`` [s] and ``latlon`` (K, 2) [deg], rounded."""
    name: str
    colour: str
    time: np.ndarray
    latlon: np.ndarray
    #: the stretches inside each outage window: ``(start_s, end_s, time, latlon)``
    spans: list = field(default_factory=list)


@dataclass
class MapLayers:
    tracks: list[Track]
    gnss: np.ndarray | None      # (K, 2) [deg]
    #: a static receiver's surveyed point: latitude, longitude [deg] (rounded), height [m]
    point: tuple[float, float, float] | None = None

    def bounds(self) -> list[list[float]]:
        pts = [t.latlon for t in self.tracks if len(t.latlon)]
        if self.gnss is not None and len(self.gnss):
            pts.append(self.gnss)
        if self.point is not None:
            pts.append(np.array([self.point[:2]]))
        allp = np.vstack(pts)
        return [[float(allp[:, 0].min()), float(allp[:, 1].min())],
                [float(allp[:, 0].max()), float(allp[:, 1].max())]]


def decimation_index(time: np.ndarray, max_points: int = MAX_POINTS,
                     outages: Sequence[tuple[float, float]] = ()) -> np.ndarray:
    """Indices kept of a track of ``len(time)`` samples: every k-th (k the smallest that keeps at
    most ``max_points``), the last, and the first and last inside each outage window."""
    n = len(time)
    if n == 0:
        return np.zeros(0, dtype=int)
    step = max(1, -(-n // max(int(max_points), 2)))
    keep = [np.arange(0, n, step), [n - 1]]
    for a, b in outages:
        inside = np.flatnonzero((time >= a) & (time <= b))
        if len(inside):
            keep.append([inside[0], inside[-1]])
    return np.unique(np.concatenate([np.asarray(k, dtype=int) for k in keep]))


def _finite(df: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    t = df["time_s"].to_numpy(dtype=float) if "time_s" in df else np.arange(len(df), dtype=float)
    ll = np.column_stack([df["lat_deg"].to_numpy(dtype=float), df["lon_deg"].to_numpy(dtype=float)])
    ok = np.isfinite(ll).all(axis=1) & np.isfinite(t)
    return t[ok], ll[ok]


def _track(name: str, colour: str, df: pd.DataFrame, outages, max_points: int) -> Track:
    t, ll = _finite(df)
    k = decimation_index(t, max_points, outages)
    tr = Track(name, colour, t[k], np.round(ll[k], DECIMALS))
    for a, b in outages:
        inside = np.flatnonzero((t >= a) & (t <= b))
        if len(inside) < 2:
            continue
        j = inside[decimation_index(t[inside], max_points)]
        tr.spans.append((float(a), float(b), t[j], np.round(ll[j], DECIMALS)))
    return tr


def map_layers(solutions: dict[str, pd.DataFrame], reference: pd.DataFrame | None = None,
               gnss: pd.DataFrame | None = None, outages: Sequence[tuple[float, float]] = (),
               max_points: int = MAX_POINTS,
               reference_point: tuple[float, float, float] | None = None) -> MapLayers:
    """What the map draws: the reference (black) and each method's track (matplotlib's
    ``C0``, ``C1``, ... as in the figures) with their outage spans, the GNSS fixes, and
    ``reference_point`` (latitude, longitude [deg], height [m]: a static receiver's
    surveyed point). Rows with a non-finite position are left out."""
    from matplotlib.colors import to_hex

    outages = [(float(a), float(b)) for a, b in outages]
    tracks = []
    if reference is not None and len(reference) > 1:
        tracks.append(_track("reference", _REFERENCE_COLOUR, reference, outages, max_points))
    for j, (name, df) in enumerate(solutions.items()):
        tracks.append(_track(str(name), to_hex(f"C{j % 10}"), df, outages, max_points))
    tracks = [t for t in tracks if len(t.latlon)]
    fixes = None
    if gnss is not None and len(gnss):
        _, ll = _finite(gnss)
        fixes = np.round(ll[decimation_index(np.zeros(len(ll)), max_points)], DECIMALS)
    point = None
    if reference_point is not None:
        lat, lon, h = (float(v) for v in reference_point)
        if not np.isfinite([lat, lon, h]).all():
            raise ValueError(f"reference_point must be finite (latitude, longitude [deg], height [m]), got "
                             f"{tuple(reference_point)}")
        point = (round(lat, DECIMALS), round(lon, DECIMALS), h)
    return MapLayers(tracks, fixes, point)


def point_popup(point: tuple[float, float, float]) -> str:
    """The text of the surveyed point's popup: its name and coordinates."""
    lat, lon, h = point
    return f"{POINT_NAME}: latitude {lat:.{DECIMALS}f} deg, longitude {lon:.{DECIMALS}f} deg, height {h:.3f} m"


def _leaflet_popup(text_html: str):
    """A popup bound to its parent by Leaflet alone: folium's ``Popup`` builds its content with
    jQuery, which this page does not load."""
    from branca.element import MacroElement
    from jinja2 import Template

    popup = MacroElement()
    popup._name = "LeafletPopup"
    # a JavaScript string literal ('</' split so that no '</script>' can end the page's script)
    popup.content_js = json.dumps(text_html).replace("</", "<\\/")
    popup._template = Template("{% macro script(this, kwargs) %}{{ this._parent.get_name() }}.bindPopup("
                               "{{ this.content_js }}, {maxWidth: 360});{% endmacro %}")
    return popup


def map_html(solutions: dict[str, pd.DataFrame], reference: pd.DataFrame | None = None,
             gnss: pd.DataFrame | None = None, outages: Sequence[tuple[float, float]] = (),
             title: str = "trajectories", max_points: int = MAX_POINTS,
             reference_point: tuple[float, float, float] | None = None) -> str | None:
    """The map page (a whole HTML document), or None when there is no position to draw."""
    layers = map_layers(solutions, reference, gnss, outages, max_points, reference_point)
    if not layers.tracks and (layers.gnss is None or not len(layers.gnss)) and layers.point is None:
        return None
    import folium

    m = folium.Map(tiles=None, prefer_canvas=True, control_scale=True)
    # Leaflet alone: folium's other defaults (jQuery, Bootstrap, icon fonts) serve its icon
    # markers and popups, which this page does not use (its one popup is Leaflet's own), and
    # each is one more host to reach
    m.default_js = [(k, v) for k, v in m.default_js if k == "leaflet"]
    m.default_css = [(k, v) for k, v in m.default_css if k == "leaflet_css"]
    folium.TileLayer("OpenStreetMap", name="OpenStreetMap", control=False).add_to(m)
    m.get_root().header.add_child(folium.Element(f"<title>{html.escape(title)}</title>"))

    spans = [(t, s) for t in layers.tracks for s in t.spans]
    if spans:
        g = folium.FeatureGroup(name="GNSS outage windows (orange)")
        for tr, (a, b, _, ll) in spans:
            folium.PolyLine(ll.tolist(), color=_OUTAGE_COLOUR, weight=9, opacity=0.55,
                            tooltip=html.escape(f"{tr.name}: GNSS outage {a:g} - {b:g} s")).add_to(g)
        g.add_to(m)
    if layers.gnss is not None and len(layers.gnss):
        geo = {"type": "Feature", "properties": {},
               "geometry": {"type": "MultiPoint", "coordinates": layers.gnss[:, ::-1].tolist()}}
        g = folium.FeatureGroup(name="GNSS fixes (grey)")
        folium.GeoJson(geo, marker=folium.CircleMarker(radius=2, color=_GNSS_COLOUR, fill=True,
                                                       fill_opacity=0.8, weight=0)).add_to(g)
        g.add_to(m)
    for tr in layers.tracks:
        g = folium.FeatureGroup(name=html.escape(tr.name))
        folium.PolyLine(tr.latlon.tolist(), color=tr.colour, weight=3 if tr.name == "reference" else 2,
                        opacity=0.9, tooltip=html.escape(tr.name)).add_to(g)
        g.add_to(m)
    if layers.point is not None:
        # a circle marker (drawn by Leaflet, no icon images to fetch), on top of the fixes
        g = folium.FeatureGroup(name=html.escape(POINT_NAME))
        text = html.escape(point_popup(layers.point))
        marker = folium.CircleMarker(list(layers.point[:2]), radius=7, color="#ffffff", weight=2, fill=True,
                                     fill_color=_REFERENCE_COLOUR, fill_opacity=1.0,
                                     tooltip=html.escape(POINT_NAME)).add_to(g)
        _leaflet_popup(text).add_to(marker)
        g.add_to(m)
    control = folium.LayerControl(collapsed=False).add_to(m)
    bounds = layers.bounds()
    m.fit_bounds(bounds)
    # In the report's iframe the map may have no size yet when the page's script runs (zoom 0,
    # the whole world; a layer list cut to a scrolling sliver): fit both again once the frame
    # is laid out
    name = m.get_name()
    m.get_root().script.add_child(folium.Element(
        f"window.addEventListener('load', function () {{ {name}.invalidateSize(); "
        f"{name}.fitBounds({json.dumps(bounds)}); {control.get_name()}.expand(); }});"))
    return m.get_root().render()
