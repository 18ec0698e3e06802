"""Report, figures and atomic writers end to end on two synthetic solutions."""

import base64
import json
import re

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from mixnav.experiment import figures
from mixnav.experiment.metrics import compute_metrics
from mixnav.experiment.report import write_report
from mixnav.io.atomic import (
    atomic_savefig,
    atomic_write_bytes,
    atomic_write_dataframe,
    atomic_write_json,
    atomic_write_text,
)

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
OUTAGES = [(40.0, 60.0)]


def synthetic_solution(scale: float, with_sigma: bool, n=121) -> pd.DataFrame:
    t = np.arange(n) * 1.0
    rng = np.random.default_rng(int(scale * 10))
    d = {"time_s": t, "lat_deg": 30.0 + t * 1e-5, "lon_deg": 114.0 + np.sin(t / 20) * 1e-4,
         "height_m": np.full(n, 20.0), "vn_mps": np.full(n, 1.1), "ve_mps": np.zeros(n),
         "vd_mps": np.zeros(n), "roll_deg": np.zeros(n), "pitch_deg": np.zeros(n), "yaw_deg": np.zeros(n)}
    for c, u in [("n", "m"), ("e", "m"), ("d", "m"), ("vn", "mps"), ("ve", "mps"), ("vd", "mps"),
                 ("roll", "deg"), ("pitch", "deg"), ("yaw", "deg")]:
        d[f"err_{c}_{u}"] = scale * rng.standard_normal(n)
        if with_sigma:
            d[f"sig_{c}_{u}"] = np.full(n, scale)
    d["gnss_used"] = (t % 1 == 0) & ~((t >= 40) & (t <= 60))
    d["in_outage"] = (t >= 40) & (t <= 60)
    return pd.DataFrame(d)


@pytest.fixture
def solutions():
    return {"ekf": synthetic_solution(1.0, True), "gmm<robust>": synthetic_solution(2.0, False)}


def test_report_writes_pngs_and_one_self_contained_page(tmp_path, solutions):
    metrics = {"scenario": "synthetic",
               "methods": {n: compute_metrics(s, OUTAGES) | {"epoch_time_mean_us": 12.34}
                           for n, s in solutions.items()}}
    ref = solutions["ekf"][["time_s", "lat_deg", "lon_deg"]]
    figs = {f"errors_{k}": figures.error_figure(solutions, k, OUTAGES)
            for k in ("attitude", "velocity", "position")}
    figs["horizontal_error"] = figures.horizontal_error_figure(solutions, OUTAGES)
    figs["trajectory"] = figures.trajectory_figure(solutions, ref, ref.iloc[::5], OUTAGES)
    path = write_report(tmp_path, "test <report>", metrics, figs, notes=["a & b"],
                        config_text="[scenario]\nname = \"<x>\"\n")

    assert path == tmp_path / "report.html"
    page = path.read_text()
    for name in figs:
        assert (tmp_path / f"{name}.png").read_bytes()[:8] == PNG_MAGIC
    imgs = re.findall(r"<img src=['\"]data:image/png;base64,([A-Za-z0-9+/=]+)['\"]", page)
    assert len(imgs) == len(figs) == page.count("<img")
    for name, b64 in zip(figs, imgs):
        assert base64.b64decode(b64) == (tmp_path / f"{name}.png").read_bytes()
    # metrics table: each method (escaped) with its horizontal RMSE to 3 significant digits
    for name, m in metrics["methods"].items():
        row = re.search(rf"<tr><td>{re.escape(name.replace('<', '&lt;').replace('>', '&gt;'))}</td>.*?</tr>", page)
        assert row, name
        assert f"<td>{m['horizontal_rmse_m']:.3g}</td>" in row.group(0)
        assert "<td>12.3</td>" in row.group(0)
    assert "horiz. RMSE [m]" in page and "time/epoch [us]" in page
    assert "GNSS outages" in page and "40 - 60" in page
    # all text escaped; nothing executable or external
    assert "test &lt;report&gt;" in page and "a &amp; b" in page and "&lt;x&gt;" in page
    assert "<script" not in page.lower() and "http" not in page
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_error_figure_draws_sigma_only_where_present(solutions):
    fig = figures.error_figure(solutions, "position", OUTAGES)
    axs = fig.get_axes()
    assert len(axs) == 3
    # ekf: line + two dashed; gmm: line only
    assert len(axs[0].get_lines()) == 4
    assert axs[0].get_ylabel() == "north [m]" and axs[2].get_xlabel() == "time [s]"
    with pytest.raises(ValueError, match="kind"):
        figures.error_figure(solutions, "heading")


def test_trajectory_is_metres_about_first_point(solutions):
    s = solutions["ekf"]
    fig = figures.trajectory_figure({"ekf": s}, None, None)
    (line,) = fig.get_axes()[0].get_lines()
    e, n = line.get_data()
    assert e[0] == 0.0 and n[0] == 0.0
    # 1e-5 deg of latitude per second is about 1.11 m north per second
    assert n[1] == pytest.approx(1.109, abs=0.01)


def test_json_with_nan_raises_and_leaves_nothing(tmp_path):
    target = tmp_path / "metrics.json"
    with pytest.raises(ValueError, match=r"\$\.methods\.ekf\.outages\[0\]\.horizontal_max_m"):
        atomic_write_json(target, {"methods": {"ekf": {"outages": [{"horizontal_max_m": float("nan")}]}}})
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match=r"\$\.x\[1\]"):
        atomic_write_json(target, {"x": [1.0, np.float32("inf")]})
    assert list(tmp_path.iterdir()) == []


def test_failed_write_leaves_old_target_untouched(tmp_path):
    target = tmp_path / "metrics.json"
    atomic_write_json(target, {"a": 1.5, "b": np.float64(2.0), "c": np.arange(2)})
    before = target.read_bytes()
    assert json.loads(before) == {"a": 1.5, "b": 2.0, "c": [0, 1]}
    with pytest.raises(ValueError):
        atomic_write_json(target, {"a": float("nan")})
    with pytest.raises(TypeError):
        atomic_write_json(target, {"a": object()})  # fails while serialising
    assert target.read_bytes() == before
    fig = Figure()
    with pytest.raises(Exception):
        atomic_savefig(fig, tmp_path / "f.png", no_such_option=1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["metrics.json"]


def test_text_bytes_and_tables_round_trip(tmp_path, solutions):
    atomic_write_text(tmp_path / "sub" / "a.txt", "héllo\n")
    assert (tmp_path / "sub" / "a.txt").read_text(encoding="utf-8") == "héllo\n"
    atomic_write_bytes(tmp_path / "b.bin", b"\x00\x01")
    assert (tmp_path / "b.bin").read_bytes() == b"\x00\x01"
    df = solutions["ekf"]
    atomic_write_dataframe(tmp_path / "s.csv", df)
    atomic_write_dataframe(tmp_path / "s.parquet", df)
    pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "s.parquet"), df)
    csv = pd.read_csv(tmp_path / "s.csv")
    assert list(csv.columns) == list(df.columns)
    np.testing.assert_allclose(csv["err_n_m"], df["err_n_m"], rtol=1e-9)
    with pytest.raises(ValueError, match="xlsx"):
        atomic_write_dataframe(tmp_path / "s.xlsx", df)
    fig = figures.horizontal_error_figure(solutions)
    atomic_savefig(fig, tmp_path / "h.png", dpi=50)
    assert (tmp_path / "h.png").read_bytes()[:8] == PNG_MAGIC
    assert not [p for p in tmp_path.rglob("*.tmp")]
