"""The mixnav command end to end: the demo writes a complete, consistent folder."""

import base64
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import mixnav
from mixnav.cli import app
from mixnav.experiment.metrics import METRIC_KEYS_DOC

runner = CliRunner()
DOCS = Path(__file__).resolve().parents[1] / "docs"


@pytest.fixture(scope="module")
def demo_out(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    res = runner.invoke(app, ["run", "loose-demo", "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out


def test_demo_writes_solution_metrics_figures_report(demo_out):
    names = {p.name for p in demo_out.iterdir()}
    for f in ("solution_ekf.csv", "solution_ekf.parquet", "metrics.json", "report.html",
              "errors_position.png", "trajectory.png", "map.html"):
        assert f in names
    assert not [n for n in names if n.endswith(".tmp")]
    csv = pd.read_csv(demo_out / "solution_ekf.csv")
    pq = pd.read_parquet(demo_out / "solution_ekf.parquet")
    assert list(csv.columns) == list(pq.columns)
    pd.testing.assert_frame_equal(csv[["time_s", "err_n_m"]], pq[["time_s", "err_n_m"]], rtol=1e-9,
                                  check_dtype=False)
    metrics = json.loads((demo_out / "metrics.json").read_text())
    m = metrics["methods"]["ekf"]
    # every key is documented, and the documented accuracy keys are present
    assert set(m) - {"outages"} <= set(METRIC_KEYS_DOC)
    for k in ("roll_rmse_deg", "pitch_max_deg", "yaw_rmse_deg", "horizontal_rmse_m", "horizontal_max_m",
              "vertical_rmse_m", "velocity_max_mps", "epoch_time_mean_us"):
        assert k in m
    # metrics agree with the solution file
    h = (csv.err_n_m ** 2 + csv.err_e_m ** 2) ** 0.5
    assert m["horizontal_max_m"] == pytest.approx(h.max(), rel=1e-8)
    assert m["outages"][0]["start_s"] == 300.0
    assert sum(m["recoveries"].values()) == 0


def test_map_holds_the_solution_and_the_outage(demo_out):
    from mixnav.experiment.webmap import decimation_index
    from .test_webmap import polylines
    page = (demo_out / "map.html").read_text()
    assert "map.html" in (demo_out / "report.html").read_text()
    csv = pd.read_csv(demo_out / "solution_ekf.csv")
    ref = pd.read_parquet(demo_out / "reference.parquet")
    window = json.loads((demo_out / "metrics.json").read_text())["outages_s"]
    lines = polylines(page)   # spans first (under the tracks), then the reference, then ekf
    assert len(lines) == 2 * len(window) + 2
    for line, df in zip(lines[-2:], (ref, csv)):
        k = decimation_index(df.time_s.to_numpy(), 3000, window)
        np.testing.assert_allclose(line, df[["lat_deg", "lon_deg"]].to_numpy()[k], rtol=0, atol=6e-8)
    for (a, b) in window:
        assert f"ekf: GNSS outage {a:g} - {b:g} s" in page


def test_report_embeds_every_figure(demo_out):
    html = (demo_out / "report.html").read_text()
    imgs = re.findall(r"src='data:image/png;base64,([^']+)'", html)
    pngs = sorted(demo_out.glob("*.png"))
    assert len(imgs) == len(pngs) >= 5
    for b in imgs:
        assert base64.b64decode(b)[:8] == b"\x89PNG\r\n\x1a\n"
    assert "ekf" in html and "GNSS outages" in html


def test_smoothed_method_shows_its_own_time(tmp_path, monkeypatch):
    """A smoothed method's table row and metrics carry the smoother's time, not the
    forward pass's per-epoch time copied from the causal method."""
    import mixnav.cli
    # the console's width is fixed when it is made if COLUMNS is set then (a test runner's
    # worker may set it): widen it here so no cell wraps
    monkeypatch.setattr(mixnav.cli.out, "width", 200)
    out = tmp_path / "veh"
    res = runner.invoke(app, ["run", "vehicle-demo", "--out", str(out)], env={"COLUMNS": "200"})
    assert res.exit_code == 0, res.output
    methods = json.loads((out / "metrics.json").read_text())["methods"]
    causal, smoothed = methods["aided"], methods["aided-smoothed"]
    assert set(smoothed) - {"outages"} <= set(METRIC_KEYS_DOC)
    assert smoothed["smoother_time_s"] > 0 and "smoother_time_s" not in causal
    for k in ("epoch_time_mean_us", "update_time_mean_us", "wall_time_s", "total_time_s", "measurement_epochs"):
        assert k in causal and k not in smoothed, k
    rows = {r.split("│")[1].strip(): [c.strip() for c in r.split("│")[2:-1]]
            for r in res.output.splitlines() if r.startswith("│")}
    assert rows["aided-smoothed"][4:] == ["-", f"{smoothed['smoother_time_s']:.3g}"], rows
    assert rows["aided"][4:] == [f"{causal['epoch_time_mean_us']:.3g}", "-"], rows
    html = (out / "report.html").read_text()
    assert "<th>smoother [s]</th>" in html
    # the time/epoch cell of the smoothed method is blank, its smoother cell filled
    assert f"<td></td><td>{smoothed['smoother_time_s']:.3g}</td></tr>" in html


def test_docs_list_every_metric_key():
    text = (DOCS / "outputs.md").read_text()
    for key in METRIC_KEYS_DOC:
        assert f"`{key}`" in text, key


def test_scenarios_lists_the_demo():
    res = runner.invoke(app, ["scenarios"])
    assert res.exit_code == 0 and "loose-demo" in res.output


def test_bad_scenario_exits_2_with_located_message(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text('[scenario]\nname = "x"\nsede = 3\n')
    res = runner.invoke(app, ["run", str(p), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert "bad.toml" in res.output and "scenario.sede" in res.output
    assert not (tmp_path / "o").exists()


def test_diagnose_command(tmp_path):
    import numpy as np
    rng = np.random.default_rng(0)
    x = np.zeros(3000)
    for k in range(1, 3000):  # AR(1) with psi = 0.8: coloured
        x[k] = 0.8 * x[k - 1] + rng.standard_normal()
    pd.DataFrame({"res": x}).to_csv(tmp_path / "r.csv", index=False)
    res = runner.invoke(app, ["diagnose", str(tmp_path / "r.csv"), "--column", "res", "--out", str(tmp_path / "d")])
    assert res.exit_code == 0, res.output
    d = json.loads((tmp_path / "d" / "diagnostics.json").read_text())
    assert d["ar1"]["coefficient"] == pytest.approx(0.8, abs=0.03) and d["verdict"]["coloured"]
    bad = runner.invoke(app, ["diagnose", str(tmp_path / "r.csv"), "--column", "nope", "--out", str(tmp_path / "e")])
    assert bad.exit_code == 2 and "nope" in bad.output


def test_experiment_command_writes_results_and_summary(tmp_path):
    res = runner.invoke(app, ["experiment", "loose-demo", "--runs", "2", "--out", str(tmp_path / "x"),
                              "--workers", "1", "--no-progress"])
    assert res.exit_code == 0, res.output
    summary = pd.read_csv(tmp_path / "x" / "summary.csv")
    row = summary[(summary.method == "ekf") & (summary.metric == "horizontal_rmse_m")].iloc[0]
    results = pd.read_parquet(tmp_path / "x" / "results.parquet")
    assert row["n"] == 2 and row["mean"] == pytest.approx(results["horizontal_rmse_m"].mean())
    html = (tmp_path / "x" / "report.html").read_text()
    assert "mixnav experiment" in html and f"{row['mean']:.4g} ± {row['ci95_half']:.2g}" in html
    assert (tmp_path / "x" / "boxplots.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = runner.invoke(app, ["experiment", "loose-demo", "--runs", "0", "--out", str(tmp_path / "y")])
    assert bad.exit_code == 2 and "--runs" in bad.output
    # rewritten without figures (resumed: nothing rerun): the same tables, no PNG left behind
    # from the first write (it would show the figures of another write), the report says why
    res = runner.invoke(app, ["experiment", "loose-demo", "--runs", "2", "--out", str(tmp_path / "x"),
                              "--workers", "1", "--no-progress", "--resume", "--no-figures"])
    assert res.exit_code == 0, res.output
    pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "x" / "results.parquet"), results)
    assert not list((tmp_path / "x").glob("*.png"))
    html = (tmp_path / "x" / "report.html").read_text()
    assert "Figures not drawn" in html and "<img" not in html
    assert f"{row['mean']:.4g} ± {row['ci95_half']:.2g}" in html
    marker = json.loads((tmp_path / "x" / ".mixnav-output.json").read_text())
    assert marker["complete"] and not [f for f in marker["files"] if f.endswith(".png")]
    # the same folder from Python (resumed: nothing rerun): the command's tables, returned
    r = mixnav.run_experiment("loose-demo", 2, tmp_path / "x", workers=1, resume=True, figures=False)
    pd.testing.assert_frame_equal(r.results, results)
    got = r.summary[(r.summary.method == "ekf") & (r.summary.metric == "horizontal_rmse_m")].iloc[0]
    assert (got["mean"], got["ci95_half"], got["n"]) == pytest.approx((row["mean"], row["ci95_half"], row["n"]))


def test_the_command_needs_no_click_of_its_own():
    """The base install has no click: typer >= 0.2x carries its own, and the one
    the test extra pulls in (through dask) hid a direct ``import click`` from CI.
    With ``click`` made unimportable, the command still runs and a usage error
    still ends in click's usage message and exit status 2, not a crash."""
    import subprocess
    import sys
    code = ("import sys; sys.modules['click'] = None\n"
            "from typer.testing import CliRunner\n"
            "from mixnav.cli import app\n"
            "r = CliRunner().invoke(app, ['run', 'loose-demo', '--bogus'])\n"
            "print(r.exit_code)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "2"


def test_python_dash_m_runs_the_same_command_line(tmp_path):
    """``python -m mixnav`` is the ``mixnav`` command (an environment without its scripts folder
    on PATH): the version it prints is the package's, and a bad argument exits with the CLI's
    usage code 2, naming the option."""
    import subprocess
    import sys
    out = subprocess.run([sys.executable, "-m", "mixnav", "--version"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and mixnav.__version__ in out.stdout, out
    bad = subprocess.run([sys.executable, "-m", "mixnav", "tune", "drive-0708", "--out", str(tmp_path / "t"),
                          "--budget", "-1"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "budget" in (bad.stdout + bad.stderr), bad
