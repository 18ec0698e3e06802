"""Monte Carlo per-epoch statistics, sweeps and the experiment report."""

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from mixnav.config.loader import load_scenario, resolve, sweep_variants
from mixnav.errors import ConfigError
from mixnav.experiment.mc_series import consistency_table, summarise_series
from mixnav.experiment.montecarlo import (TIMING_METRICS, aggregate, paired_comparison,
                                          run_experiment, series_files, write_experiment_outputs)
from mixnav.experiment.run import method_metrics, run_scenario, solution_table
from mixnav.experiment.montecarlo import flatten_metrics


def _write_series(path: Path, rng, n_epochs=200, method="m", dof=3, shift=1.0):
    t = np.arange(1.0, n_epochs + 1)
    err = rng.standard_normal((n_epochs, 3)) * 2.0
    df = pd.DataFrame({"method": method, "time_s": t,
                       "err_n_m": err[:, 0], "err_e_m": err[:, 1], "err_d_m": err[:, 2],
                       "sig_n_m": 2.0, "sig_e_m": 2.0, "sig_d_m": 2.0,
                       "nees_pos": shift * rng.chisquare(dof, n_epochs),
                       "gnss_used": True, "in_outage": False,
                       "nis": rng.chisquare(6, n_epochs), "nis_dim": 6.0})
    df.to_parquet(path)
    return df


def test_series_statistics_equal_a_direct_computation(tmp_path):
    rng = np.random.default_rng(0)
    frames = [_write_series(tmp_path / f"s{i}.parquet", rng) for i in range(7)]
    # one run misses its last 20 epochs: the per-epoch counts must follow
    frames[3] = frames[3].iloc[:-20]
    frames[3].to_parquet(tmp_path / "s3.parquet")
    out = summarise_series(sorted(tmp_path.glob("s*.parquet")))
    allf = pd.concat(frames)
    g = allf.groupby("time_s")
    np.testing.assert_array_equal(out["n_runs"], g.size().to_numpy())
    np.testing.assert_allclose(out["rms_err_n_m"], np.sqrt(g["err_n_m"].apply(lambda x: np.mean(x ** 2))),
                               rtol=1e-12)
    np.testing.assert_allclose(out["mean_nees_pos"], g["nees_pos"].mean(), rtol=1e-12)
    np.testing.assert_allclose(out["mean_nis_per_dof"], g["nis"].mean() / 6, rtol=1e-12)
    n = out["n_runs"].to_numpy()
    np.testing.assert_allclose(out["nees_pos_hi"], stats.chi2.ppf(0.975, 3 * n) / n)
    np.testing.assert_allclose(out["nis_lo"], stats.chi2.ppf(0.025, 6 * n) / (6 * n))


def test_band_holds_95_percent_of_consistent_epochs_and_flags_an_inconsistent_filter(tmp_path):
    # Independent chi-square NEES and NIS: the in-band fraction is binomial(2000, 0.95),
    # standard deviation 0.5 %; 2 % tolerance is four of them.
    rng = np.random.default_rng(1)
    for i in range(10):
        _write_series(tmp_path / f"ok{i}.parquet", rng, n_epochs=2000, method="ok")
        _write_series(tmp_path / f"bad{i}.parquet", rng, n_epochs=2000, method="bad", shift=2.0)
    cons = consistency_table(summarise_series(sorted(tmp_path.glob("*.parquet"))))
    ok = cons[cons.method == "ok"].set_index("quantity")
    bad = cons[cons.method == "bad"].set_index("quantity")
    assert ok.loc["NEES pos", "in_band_fraction"] == pytest.approx(0.95, abs=0.02)
    assert ok.loc["NIS per dof", "in_band_fraction"] == pytest.approx(0.95, abs=0.02)
    assert ok.loc["NEES pos", "mean"] == pytest.approx(3, rel=0.02)
    # NEES twice too large: 10 x mean NEES / 2 ~ chi2(30), so the fraction left inside
    # the band is known in closed form (about 0.2) and far from 0.95
    lo, hi = stats.chi2.ppf([0.025, 0.975], 30)
    expect = stats.chi2.cdf(hi / 2, 30) - stats.chi2.cdf(lo / 2, 30)
    assert bad.loc["NEES pos", "in_band_fraction"] == pytest.approx(expect, abs=4 * np.sqrt(
        expect * (1 - expect) / 2000))
    assert expect < 0.3


SWEEP = """
[sweep]
name = "position sigma"
values = [1.5, 4.0]
set = { "gnss.position_sigma" = [["1.5 m", "1.5 m", "3 m"], ["4 m", "4 m", "3 m"]] }
"""


@pytest.fixture(scope="module")
def sweep_file(tmp_path_factory):
    text, _ = resolve("loose-demo")
    d = tmp_path_factory.mktemp("sweep")
    p = d / "sweep.toml"
    p.write_text(text + SWEEP)
    # the second variant written out as a plain scenario file: the oracle
    q = d / "plain.toml"
    q.write_text(text.replace('position_sigma = ["1.5 m", "1.5 m", "3 m"]',
                              'position_sigma = ["4 m", "4 m", "3 m"]'))
    return p, q


def test_sweep_variant_is_the_scenario_with_that_value(sweep_file):
    p, q = sweep_file
    sc, source, text = load_scenario(str(p))
    (v0, s0), (v1, s1) = sweep_variants(sc, text, source)
    assert (v0, v1) == (1.5, 4.0)
    plain, src, _ = load_scenario(str(q))
    assert s1.gnss == plain.gnss and s1.methods == plain.methods and s1.sweep is None
    # same seed, same numbers: the sweep changes nothing but the swept key
    a, b = run_scenario(s1, source, 4), run_scenario(plain, src, 4)
    ma = flatten_metrics(method_metrics(a.results["ekf"], solution_table(
        a.results["ekf"], a.sim.truth, a.sim.outages), a.sim.outages))
    mb = flatten_metrics(method_metrics(b.results["ekf"], solution_table(
        b.results["ekf"], b.sim.truth, b.sim.outages), b.sim.outages))
    for k in ma:
        if k not in TIMING_METRICS:
            assert ma[k] == mb[k], k


def test_sweep_experiment_records_summary_and_report(sweep_file, tmp_path):
    p, _ = sweep_file
    out = tmp_path / "x"
    df = run_experiment(str(p), 2, out, workers=1, progress=False)
    names = sorted(f.name for f in (out / "runs").glob("run_*.parquet"))
    assert names == ["run_0_v0.parquet", "run_0_v1.parquet", "run_1_v0.parquet", "run_1_v1.parquet"]
    assert sorted(df["sweep_value"].unique()) == [1.5, 4.0]
    man = json.loads((out / "manifest.json").read_text())
    assert man["sweep"] == {"name": "position sigma", "values": [1.5, 4.0]}
    # larger fix noise -> larger horizontal error, seed by seed
    wide = df.pivot(index="seed", columns="sweep_value", values="horizontal_rmse_m")
    assert (wide[4.0] > wide[1.5]).all()
    summ = aggregate(df)
    assert list(summ.columns[:2]) == ["sweep_value", "method"]
    row = summ[(summ.sweep_value == 4.0) & (summ.metric == "horizontal_rmse_m")].iloc[0]
    assert row["mean"] == pytest.approx(wide[4.0].mean())
    with pytest.raises(ConfigError, match="no results at sweep value"):
        paired_comparison(df, "horizontal_rmse_m", "ekf", "ekf", sweep_value=9.0)
    files, values = series_files(out)
    assert sorted(values) == [1.5, 1.5, 4.0, 4.0] and len(files) == 4
    tables = write_experiment_outputs(str(p), df, out)
    assert set(tables["series"]["sweep_value"]) == {1.5, 4.0}
    html = (out / "report.html").read_text()
    assert "sweep.png" not in html and "data:image/png;base64" in html  # embedded, not linked
    assert (out / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # resuming with more seeds runs only the missing (seed, value) pairs
    kept = (out / "runs" / "run_0_v1.parquet").stat().st_mtime_ns
    df3 = run_experiment(str(p), 3, out, workers=1, resume=True, progress=False)
    assert (out / "runs" / "run_0_v1.parquet").stat().st_mtime_ns == kept
    assert len(df3) == 6


@pytest.mark.parametrize("sweep, key, message", [
    ('name = "s"\nvalues = [1, 2]\nset = { "gnss.position_sigma" = [["1 m", "1 m", "1 m"]] }',
     "sweep", "has 1 entries"),
    ('name = "s"\nvalues = [1]\nset = { "gnss.nosuch.x" = [1] }', 'sweep.set."gnss.nosuch.x"[0]',
     "no key 'gnss.nosuch'"),
    ('name = "s"\nvalues = [1]\nset = { "methods[3].states" = [17] }', 'sweep.set."methods[3].states"[0]',
     "out of range"),
    ('name = "s"\nvalues = [1, 2]\nset = { "methods[0].states" = [15, 16] }', "methods[0].states",
     "sweep value 2"),
    ('name = "s"\nvalues = [1, 1]\nset = { "methods[0].states" = [15, 17] }', "sweep", "distinct"),
])
def test_bad_sweeps_name_the_key(tmp_path, sweep, key, message):
    text, _ = resolve("loose-demo")
    p = tmp_path / "bad.toml"
    p.write_text(text + "\n[sweep]\n" + sweep + "\n")
    with pytest.raises(ConfigError, match=re.escape(message)) as exc:
        load_scenario(str(p))
    assert exc.value.key is not None and exc.value.key.startswith(key)
    assert exc.value.file == str(p)


def test_summary_cell_is_blank_where_no_run_has_the_metric():
    """A smoothed method has no forward-pass epoch time: its cell is blank, not 'nan'."""
    from mixnav.experiment.mc_report import _mean_ci_table
    df = pd.DataFrame({"method": ["aided", "aided", "aided-smoothed", "aided-smoothed"], "seed": [0, 1, 0, 1],
                       "horizontal_rmse_m": [0.5, 0.7, 0.3, 0.4],
                       "epoch_time_mean_us": [90.0, 110.0, np.nan, np.nan],
                       "smoother_time_s": [np.nan, np.nan, 0.1, 0.2]})
    summ = aggregate(df)
    wide = _mean_ci_table(summ, {"horizontal_rmse_m": "h", "epoch_time_mean_us": "t"}).set_index("method")
    assert wide.loc["aided-smoothed", "t"] == "" and wide.loc["aided", "t"].startswith("100 ±")
    assert wide.loc["aided-smoothed", "h"].startswith("0.35 ±")
