"""Scored segments of a scenario (``[scoring] segments``, issue 37): the metrics of each
span against closed-form answers, the refusals naming their key, and the segment
metrics of ``mixnav run`` and ``mixnav experiment`` (results, summary, console, reports)."""

from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from mixnav.cli import app
from mixnav.config.loader import load_scenario, resolve
from mixnav.errors import ConfigError
from mixnav.experiment.metrics import METRIC_KEYS_DOC, compute_metrics, segment_metrics
from mixnav.experiment.montecarlo import flatten_metrics

runner = CliRunner()

ERR_COLS = ["err_n_m", "err_e_m", "err_d_m", "err_vn_mps", "err_ve_mps", "err_vd_mps",
            "err_roll_deg", "err_pitch_deg", "err_yaw_deg"]


def table(n=10, **cols):
    """A solution table at 0, 1, ..., n-1 s with zero errors except the columns given."""
    d = {"time_s": np.arange(float(n))}
    for c in ERR_COLS:
        d[c] = np.zeros(n)
    for k, v in cols.items():
        d[k] = np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()
    return pd.DataFrame(d)


# ----------------------------------------------------------------------------- metrics

def test_segment_metrics_closed_form():
    # north error = time, east 0; down -2 in [4, 6); velocity (1, 2, 2) -> 3 m/s everywhere;
    # position NEES 1..10 (NaN at 5 s: declined), velocity NEES 3
    n = 10
    nees_pos = np.arange(1.0, n + 1)
    nees_pos[5] = np.nan
    df = table(n, err_n_m=np.arange(float(n)), err_d_m=np.where((np.arange(n) >= 4) & (np.arange(n) < 6), -2.0, 0.0),
               err_vn_mps=1.0, err_ve_mps=2.0, err_vd_mps=2.0, err_yaw_deg=np.arange(float(n)) - 5.0,
               nees_pos=nees_pos, nees_vel=3.0)
    m = compute_metrics(df, segments=[("a", 2.0, 6.0), ("b", 6.0, 9.5)])
    a, b = m["segments"]["a"], m["segments"]["b"]
    # half open: "a" holds 2, 3, 4, 5 (not 6); "b" holds 6, 7, 8, 9 (6 is not shared)
    assert a["n_epochs"] == 4 and b["n_epochs"] == 4
    assert (a["start_s"], a["end_s"]) == (2.0, 6.0)
    assert a["horizontal_max_m"] == 5.0
    assert a["horizontal_rmse_m"] == pytest.approx(np.sqrt((4 + 9 + 16 + 25) / 4), rel=1e-14)
    assert a["vertical_max_m"] == 2.0 and a["vertical_rmse_m"] == pytest.approx(np.sqrt(2.0), rel=1e-14)
    assert a["velocity_rmse_mps"] == pytest.approx(3.0, rel=1e-14) and a["velocity_max_mps"] == pytest.approx(3.0)
    assert a["yaw_max_deg"] == 3.0 and a["yaw_rmse_deg"] == pytest.approx(np.sqrt((9 + 4 + 1 + 0) / 4), rel=1e-14)
    assert a["nees_pos_mean"] == pytest.approx((3 + 4 + 5) / 3, rel=1e-14)     # the NaN left out
    assert a["nees_singular_epochs"] == 1 and a["nees_vel_mean"] == pytest.approx(3.0)
    assert b["horizontal_max_m"] == 9.0 and b["vertical_max_m"] == 0.0
    assert b["horizontal_p95_m"] == pytest.approx(np.percentile([6, 7, 8, 9], 95), rel=1e-14)
    assert b["nees_pos_mean"] == pytest.approx((7 + 8 + 9 + 10) / 4, rel=1e-14)
    # the whole-run metrics are unchanged by the segments
    assert m["horizontal_max_m"] == 9.0 and m["n_epochs"] == n
    whole = compute_metrics(df)
    assert {k: v for k, v in m.items() if k != "segments"} == whole
    json.dumps(m, allow_nan=False)
    assert "segments" in METRIC_KEYS_DOC


def test_segment_metrics_match_the_whole_run_metrics_of_its_rows():
    rng = np.random.default_rng(3)
    df = table(50, err_n_m=rng.normal(size=50), err_e_m=rng.normal(size=50), err_d_m=rng.normal(size=50),
               err_vn_mps=rng.normal(size=50), err_pitch_deg=rng.normal(size=50))
    seg = segment_metrics(df, [("x", 10.0, 30.0)])["x"]
    ref = compute_metrics(df[(df.time_s >= 10) & (df.time_s < 30)])
    ref.pop("outages")
    assert seg == {"start_s": 10.0, "end_s": 30.0, **ref}


def test_empty_segment_is_refused_by_name():
    with pytest.raises(ValueError, match=r"segment 'gap' \[2.2, 2.8\)"):
        compute_metrics(table(), segments=[("gap", 2.2, 2.8)])


def test_flattened_as_segment_name_metric():
    m = compute_metrics(table(err_e_m=np.arange(10.0)), segments=[("multipath", 3.0, 5.0)])
    m["recoveries"] = {}
    flat = flatten_metrics(m)
    assert flat["segment_multipath_horizontal_max_m"] == 4.0
    assert flat["segment_multipath_n_epochs"] == 2
    assert "segment_multipath_start_s" not in flat          # the span is in the scenario
    assert not any(isinstance(v, (dict, list)) for v in flat.values())


# ----------------------------------------------------------------------------- config

DEMO = resolve("loose-demo")[0]


def scored(segments: str) -> str:
    return DEMO + f"\n[scoring]\nsegments = [{segments}]\n"


def load_text(tmp_path, text):
    p = tmp_path / "sc.toml"
    p.write_text(text)
    return load_scenario(str(p))[0]


def test_segments_parsed_with_units(tmp_path):
    sc = load_text(tmp_path, scored('{ name = "turn", start = "2 min", end = "400 s" }, '
                                    '{ name = "outage_1", start = "300 s", end = "360 s" }'))
    assert sc.scored_segments == [("turn", 120.0, 400.0), ("outage_1", 300.0, 360.0)]
    assert load_text(tmp_path, DEMO).scored_segments == []


@pytest.mark.parametrize("segments, key, words", [
    ('{ name = "a", start = "300 s", end = "300 s" }', "scoring.segments[0]", "after start"),
    ('{ name = "a", start = "10 s", end = "20 s" }, { name = "b", start = "300 s", end = "200 s" }',
     "scoring.segments[1]", "after start"),
    ('{ name = "a", start = "500 s", end = "700 s" }', "scoring.segments[0]", "end of the run"),
    ('{ name = "a", start = "600 s", end = "610 s" }', "scoring.segments[0]", "end of the run"),
    ('{ name = "a", start = "-5 s", end = "10 s" }', "scoring.segments[0].start", ""),
    ('{ name = "a", start = "10", end = "20 s" }', "scoring.segments[0].start", "unit"),
    ('{ name = "a", start = "10 m", end = "20 s" }', "scoring.segments[0].start", ""),
    ('{ name = "a", start = "10 s" }', "scoring.segments[0].end", "missing"),
    ('{ name = "a b", start = "10 s", end = "20 s" }', "scoring.segments[0].name", ""),
    ('{ name = "", start = "10 s", end = "20 s" }', "scoring.segments[0].name", ""),
    ('{ name = "a", start = "10 s", end = "20 s", weight = 2 }', "scoring.segments[0].weight", "unknown key"),
    ('{ name = "a", start = "10 s", end = "20 s" }, { name = "a", start = "30 s", end = "40 s" }',
     "scoring.segments[1].name", "scoring.segments[0]"),
])
def test_bad_segments_refused_naming_the_key(tmp_path, segments, key, words):
    with pytest.raises(ConfigError) as exc:
        load_text(tmp_path, scored(segments))
    assert exc.value.key == key, str(exc.value)
    assert words.lower() in str(exc.value).lower()


def test_unknown_scoring_key_refused(tmp_path):
    with pytest.raises(ConfigError) as exc:
        load_text(tmp_path, DEMO + '\n[scoring]\nsegment = []\n')
    assert exc.value.key == "scoring.segment"


# ----------------------------------------------------------------------------- run and experiment

#: the demo, 200 s with its outage at 100-130 s, two scored segments
SHORT = (DEMO.split("segments = [")[0] + """segments = [
  { type = "static",     duration = "30 s" },
  { type = "accelerate", duration = "10 s", acceleration = "1.5 m/s^2" },
  { type = "uniform",    duration = "60 s" },
  { type = "turn",       duration = "9 s",  angle = "90 deg" },
  { type = "uniform",    duration = "91 s" },
]
""" + "[imu]" + DEMO.split("[imu]", 1)[1]).replace(
    'outages = [["300 s", "360 s"]]', 'outages = [["100 s", "130 s"]]') + """
[scoring]
segments = [{ name = "outage", start = "100 s", end = "140 s" }, { name = "early", start = "0 s", end = "100 s" }]
"""


def test_run_writes_segment_metrics(tmp_path):
    p = tmp_path / "short.toml"
    p.write_text(SHORT)
    res = runner.invoke(app, ["run", str(p), "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert m["segments_s"] == {"outage": [100.0, 140.0], "early": [0.0, 100.0]}
    ekf = m["methods"]["ekf"]
    sol = pd.read_csv(tmp_path / "out" / "solution_ekf.csv")
    s = sol[(sol.time_s >= 100) & (sol.time_s < 140)]
    h = np.hypot(s.err_n_m, s.err_e_m)
    assert ekf["segments"]["outage"]["horizontal_max_m"] == pytest.approx(h.max(), rel=1e-6)
    assert ekf["segments"]["outage"]["n_epochs"] == len(s)
    assert set(ekf["segments"]["early"]) >= {"horizontal_rmse_m", "vertical_max_m", "velocity_rmse_mps",
                                             "yaw_rmse_deg", "nees_pos_mean"}
    assert "outage: horiz. max [m]" in res.output.replace("\n", " ") or "outage:" in res.output
    html = (tmp_path / "out" / "report.html").read_text()
    assert "Scored segments" in html and "100 - 140" in html


def test_experiment_reports_segment_metrics(tmp_path):
    p = tmp_path / "short.toml"
    p.write_text(SHORT)
    out = tmp_path / "exp"
    res = runner.invoke(app, ["experiment", str(p), "--runs", "2", "--workers", "1", "--out", str(out),
                              "--no-progress"])
    assert res.exit_code == 0, res.output
    df = pd.read_parquet(out / "results.parquet")
    for k in ("horizontal_rmse_m", "horizontal_max_m", "vertical_max_m", "velocity_rmse_mps", "nees_pos_mean"):
        assert f"segment_outage_{k}" in df.columns and f"segment_early_{k}" in df.columns
    assert (df["segment_outage_horizontal_max_m"] <= df["horizontal_max_m"]).all()
    summary = pd.read_csv(out / "summary.csv")
    row = summary[(summary.method == "ekf") & (summary.metric == "segment_outage_horizontal_max_m")]
    assert len(row) == 1 and row["n"].iloc[0] == 2 and np.isfinite(row["ci95_half"].iloc[0])
    # the console table shows each segment's maximum
    assert "segment_outage_horizontal_max_m" in res.output and "segment_early_horizontal_max_m" in res.output
    html = (out / "report.html").read_text()
    assert "Scored segments" in html and "outage: horizontal max [m]" in html


def test_p4_vehicle_declares_the_multipath_episode():
    sc = load_scenario("P4-vehicle")[0]
    assert ("multipath", 1200.0, 1800.0) in sc.scored_segments
    assert re.search(r'name = "multipath", start = "1200 s", end = "1800 s"', resolve("P4-vehicle")[0])


def p4_short() -> str:
    """P4-vehicle cut to its first 420 s, the multipath episode moved to 150-330 s (its scored
    segment with it), no random loss, only the IMM and the EM-IMM: about 15 s per run."""
    text = resolve("P4-vehicle")[0]
    head, rest = text.split("  # block 1: 420 - 770 s\n", 1)
    text = head + "]\n" + rest.split("\n]\n", 1)[1]
    for old, new in (('losses = [["2400 s", "3000 s", 0.3]]\n', ""),
                     ('["1200 s", 1], ["1800 s", 0]]', '["150 s", 1], ["330 s", 0]]')):
        assert old in text
        text = text.replace(old, new)
    text = (text[:text.index("[scoring]")] + '[scoring]\nsegments = [{ name = "multipath", start = "150 s", '
            'end = "330 s" }]\n\n' + text[text.index("[init]"):])
    m = text.index("[[methods]]")
    keep = [b for b in text[m:].split("[[methods]]")[1:]
            if re.match(r'\s*name = "(imm|em-imm)"', b)]
    assert len(keep) == 2
    return text[:m] + "".join("[[methods]]" + b for b in keep)


def test_p4_short_experiment_prints_the_multipath_maximum(tmp_path):
    """P4's number, the maximum horizontal error in the multipath episode, in the results and
    the console table of ``mixnav experiment`` (the EM-IMM within P4's 2 m, the IMM far beyond)."""
    p = tmp_path / "p4short.toml"
    p.write_text(p4_short())
    out = tmp_path / "exp"
    res = runner.invoke(app, ["experiment", str(p), "--runs", "1", "--workers", "1", "--out", str(out),
                              "--no-progress"])
    assert res.exit_code == 0, res.output
    df = pd.read_parquet(out / "results.parquet").set_index("method")
    em, imm = df.loc["em-imm", "segment_multipath_horizontal_max_m"], df.loc["imm", "segment_multipath_horizontal_max_m"]
    assert em <= 2.0 < imm
    assert df.loc["em-imm", "segment_multipath_n_epochs"] >= 180          # at least one epoch a second
    for method, v in (("em-imm", em), ("imm", imm)):
        assert re.search(rf"{method}\s*│\s*segment_multipath_horizontal_max_m\s*│\s*{v:.4g}\b", res.output), res.output
