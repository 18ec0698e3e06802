"""mixnav.noise.diagnostics on seeded series with known answers."""

import json

import numpy as np
import pandas as pd
import pytest

from mixnav.errors import DataError
from mixnav.experiment.diagnose import diagnose_file
from mixnav.noise.diagnostics import diagnose, figures
from mixnav.noise.processes import AR1, Mixture


def test_white_gaussian_noise_looks_white_and_gaussian():
    n = 5000
    x = np.random.default_rng(20).standard_normal(n) * 2.0 + 1.0
    r = diagnose(x, max_lag=50)
    assert not r["normality"]["rejected"] and r["normality"]["p_value"] > 0.05
    # ~95 % of lags inside the band: binomial(50, 0.05) has mean 2.5, sd 1.5; allow up to 15 %
    assert r["acf"]["fraction_outside"] <= 0.15
    assert r["acf"]["band"] == pytest.approx(1.96 / np.sqrt(n))
    # sd of the sample excess kurtosis is sqrt(24/n) = 0.07; allow 4 sd
    assert abs(r["excess_kurtosis"]) < 4 * np.sqrt(24 / n)
    assert abs(r["skewness"]) < 4 * np.sqrt(6 / n)
    assert not r["verdict"]["non_gaussian"] and not r["verdict"]["coloured"]
    assert r["mean"] == pytest.approx(1.0, abs=0.15) and r["std"] == pytest.approx(2.0, rel=0.05)
    qq = r["qq"]
    assert qq["theoretical"].shape == qq["sample"].shape == (n,)
    assert np.all(np.diff(qq["sample"]) >= 0)
    # Gaussian Q-Q points lie near the diagonal in the bulk
    mid = slice(n // 20, n - n // 20)
    assert np.max(np.abs(qq["sample"][mid] - qq["theoretical"][mid])) < 0.15


def test_ar1_is_detected_as_coloured():
    x = AR1(0.8, 1.0).sample(np.arange(20_000), 1, np.random.default_rng(21))[:, 0]
    r = diagnose(x, max_lag=30)
    # sd of the lag-1 LS estimate: sqrt((1 - 0.64) / n) = 0.004; brief asks for 0.03
    assert abs(r["ar1"]["coefficient"] - 0.8) < 0.03
    assert abs(r["acf"]["values"][1]) > r["acf"]["band"]
    assert r["verdict"]["coloured"] and r["ljung_box"]["p_value"] < 1e-10
    assert r["ar1"]["innovation_std"] == pytest.approx(1.0, rel=0.03)


def test_heavy_tailed_mixture_rejects_normality_with_the_closed_form_kurtosis():
    w, s = np.array([0.8, 0.2]), np.array([1.0, 3.0])
    m2, m4 = w @ s**2, 3 * w @ s**4
    kurt_true = m4 / m2**2 - 3                               # 4.544
    n = 100_000
    x = Mixture(w, s).sample(np.arange(n), 1, np.random.default_rng(22))[:, 0]
    r = diagnose(x, max_lag=20)
    assert r["normality"]["rejected"] and r["normality"]["p_value"] < 1e-10
    assert r["verdict"]["non_gaussian"] and not r["verdict"]["coloured"]
    # delta-method sd of the sample kurtosis here is ~0.17 (see test_noise_processes); allow 4 sd
    assert abs(r["excess_kurtosis"] - kurt_true) < 0.7
    # the mixture fit (EM) on 10^4 samples: weight sd ~0.01, sigma rel. sd ~2-4 %
    mix = diagnose(x[:10_000], max_lag=20, n_components=2)["mixture"]
    assert mix["n_components"] == 2 and mix["converged"]
    assert np.allclose(mix["weights"], w, atol=0.05)
    assert np.allclose(mix["sigmas"], s, rtol=0.1)
    # a component mean's sd is sigma_k / sqrt(n w_k): 0.011 and 0.067; allow ~4 sd
    assert np.all(np.abs(mix["means"]) < 0.1 * s)
    assert abs(mix["excess_kurtosis"] - kurt_true) < 1.0


def test_figures_are_plain_matplotlib_figures():
    from matplotlib.figure import Figure

    x = Mixture([0.9, 0.1], [1.0, 4.0]).sample(np.arange(500), 1, np.random.default_rng(23))[:, 0]
    figs = figures(diagnose(x, n_components=2))
    assert set(figs) == {"qq", "acf", "histogram"}
    assert all(isinstance(f, Figure) for f in figs.values())


def test_diagnose_argument_checks():
    with pytest.raises(ValueError, match="at least 20"):
        diagnose(np.arange(10.0))
    with pytest.raises(ValueError, match="not finite"):
        diagnose(np.r_[np.arange(30.0), np.nan])
    with pytest.raises(ValueError, match="constant"):
        diagnose(np.ones(30))
    with pytest.raises(ValueError, match="1-D"):
        diagnose(np.zeros((30, 2)))
    # max_lag is clipped to n - 1
    assert diagnose(np.random.default_rng(0).standard_normal(25))["acf"]["max_lag"] == 24


def test_diagnose_file_round_trip(tmp_path):
    rng = np.random.default_rng(24)
    csv = tmp_path / "residuals.csv"
    pd.DataFrame({"t": np.arange(300) * 0.1, "pr_res": rng.standard_normal(300)}).to_csv(csv, index=False)
    out = tmp_path / "out"
    doc = diagnose_file(csv, "pr_res", out, max_lag=25, n_components=2)
    data = json.loads((out / "diagnostics.json").read_text())
    assert data["source"] == {"file": str(csv), "column": "pr_res"}
    for key in ("n", "qq", "acf", "normality", "skewness", "excess_kurtosis", "ar1", "mixture", "verdict"):
        assert key in data
    assert data["n"] == 300 and data["acf"]["max_lag"] == 25 and len(data["acf"]["values"]) == 26
    assert len(data["mixture"]["weights"]) == 2 and doc["n"] == 300
    for name in data["figures"].values():
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(out.glob(".*tmp"))                       # no stray temporary files
    # figures can be redrawn from the JSON
    assert set(figures(data)) == {"qq", "acf", "histogram"}


def test_diagnose_file_parquet(tmp_path):
    pytest.importorskip("pyarrow")
    p = tmp_path / "r.parquet"
    pd.DataFrame({"v": np.random.default_rng(25).standard_normal(100)}).to_parquet(p)
    assert diagnose_file(p, "v", tmp_path / "o")["n"] == 100
    pd.DataFrame({"v": np.r_[np.ones(30), np.nan]}).to_parquet(p)
    with pytest.raises(DataError, match="row 30"):
        diagnose_file(p, "v", tmp_path / "o")


def _write(path, values):
    path.write_text("t,res\n" + "".join(f"{i},{v}\n" for i, v in enumerate(values)))
    return path


@pytest.mark.parametrize("values, words, line", [
    (["1.0"] * 30 + ["abc"] + ["2.0"] * 5, "not a number: 'abc'", 32),
    (["1.0"] * 12 + ["nan"] + ["2.0"] * 20, "is NaN", 14),
    (["1.0"] * 12 + [""] + ["2.0"] * 20, "empty", 14),
    (["1.0"] * 3 + ["inf"] + ["2.0"] * 20, "not finite", 5),
])
def test_diagnose_file_bad_values_name_file_column_and_row(tmp_path, values, words, line):
    f = _write(tmp_path / "bad.csv", values)
    with pytest.raises(DataError) as info:
        diagnose_file(f, "res", tmp_path / "out")
    err = info.value
    assert err.file == str(f) and err.line == line
    assert words in str(err) and "'res'" in str(err) and f"row {line - 2}" in str(err)
    assert not (tmp_path / "out" / "diagnostics.json").exists()


def test_diagnose_file_other_errors(tmp_path):
    f = _write(tmp_path / "r.csv", np.arange(30.0))
    with pytest.raises(DataError, match="no column 'resid'; columns are: t, res") as info:
        diagnose_file(f, "resid", tmp_path / "out")
    assert info.value.file == str(f)
    short = _write(tmp_path / "short.csv", np.arange(10.0))
    with pytest.raises(DataError, match="10 values; at least 20"):
        diagnose_file(short, "res", tmp_path / "out")
    with pytest.raises(DataError, match="no such file"):
        diagnose_file(tmp_path / "missing.csv", "res", tmp_path / "out")
    const = _write(tmp_path / "const.csv", np.ones(30))
    with pytest.raises(DataError, match="constant"):
        diagnose_file(const, "res", tmp_path / "out")
