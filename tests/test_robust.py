"""Robust adaptive EKF (M2): IGG-III weights and Yang's adaptive factor in
closed form, and its behaviour under P1's gross errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mixnav.config.loader import resolve
from mixnav.filters._ekf_kernels import ABSURD, OK, ekf_correct_dx
from mixnav.filters.robust_adaptive import RobustEstimator, adaptive_factor, igg3_factors
from mixnav.ins.error_model import get_layout


def test_igg3_segments():
    k0, k1 = 1.5, 3.0
    t = np.array([0.0, 1.0, 1.5, 2.0, 2.999999, 3.0, 3.1, 50.0])
    g = igg3_factors(t, k0, k1)
    assert g[0] == g[1] == g[2] == 1.0
    assert g[3] == pytest.approx((1.5 / 2.0) * ((3.0 - 2.0) / 1.5) ** 2)
    assert g[4] == pytest.approx(0.0, abs=1e-10) and g[5] == 0.0   # continuous at k1
    assert g[6] == g[7] == 0.0
    assert igg3_factors([1.5 + 1e-12], k0, k1)[0] == pytest.approx(1.0)  # continuous at k0
    assert adaptive_factor(1.0, 1.5) == 1.0 and adaptive_factor(3.0, 1.5) == 0.5


def _problem(rng, m=6):
    lay = get_layout(17)
    n = lay.n
    A = rng.standard_normal((n, n)) * 0.1
    P = A @ A.T + np.eye(n) * 0.01
    H = np.zeros((m, n))
    H[:, 6:9] = rng.standard_normal((m, 3))
    H[:, 15] = 1.0
    r = np.full(m, 0.09)
    S = np.einsum("ij,jk,ik->i", H, P, H) + r
    z = 0.5 * np.sqrt(S) * rng.choice([-1.0, 1.0], m)   # every row at t = 0.5
    nav = np.array([1.0, 0, 0, 0, 1.0, 2.0, 0.1, 0.6, 1.9, 100.0])
    return lay, P, H, r, z, S, nav


def _belief(lay, P, k0=1.5, k1=3.0, c=1.5):
    return RobustEstimator(k0, k1, c, absurd_sigma=1e4)


def test_gross_row_rejected_and_mid_row_downweighted_exactly():
    rng = np.random.default_rng(0)
    lay, P, H, r, z, S, nav = _problem(rng)
    z[2] = 8.0 * np.sqrt(S[2])      # a gross error: rejected
    z[4] = 2.0 * np.sqrt(S[4])      # down-weighted by IGG-III
    b = _belief(lay, P)
    args = (np.zeros(12), np.zeros(2), lay.as_array())
    P1, dx1, nis1, st1 = b.correct(P, z, H, r)
    keep = np.array([True, True, False, True, True, True])
    g4 = (1.5 / 2.0) * ((3.0 - 2.0) / 1.5) ** 2
    r2 = r.copy()
    r2[4] /= g4
    # the discrepancy of the kept rows is below c here, so no inflation of P
    d = np.sqrt(np.sum(igg3_factors(np.abs(z) / np.sqrt(S), 1.5, 3.0) * z ** 2) /
                np.sum(igg3_factors(np.abs(z) / np.sqrt(S), 1.5, 3.0) * S))
    assert d < 1.5
    P2, dx2, nis2, st2 = ekf_correct_dx(P, z[keep], H[keep], r2[keep], 1e4, nav.copy(), *args)
    assert st1 == st2 == OK
    np.testing.assert_allclose(dx1, dx2, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(P1, P2, rtol=1e-12, atol=1e-15)
    assert b.counts["robust_rows_rejected"] == 1 and b.counts["robust_rows_downweighted"] == 1


def test_adaptive_factor_inflates_the_prediction():
    """Every row 1.4 sigma off (kept, IGG-III weight 1): d = 1.4 < c keeps P; with
    c = 1 the prediction is inflated by 1 / alpha = d / c."""
    rng = np.random.default_rng(1)
    lay, P, H, r, z, S, nav = _problem(rng)
    z = 1.4 * np.sqrt(S)
    args = (np.zeros(12), np.zeros(2), lay.as_array())
    P_a, dx_a, _, _ = _belief(lay, P, c=1.5).correct(P, z, H, r)
    P_e, dx_e, _, _ = ekf_correct_dx(P, z, H, r, 1e4, nav.copy(), *args)
    np.testing.assert_allclose(dx_a, dx_e, rtol=1e-12)
    b = _belief(lay, P, c=1.0)
    P_b, dx_b, _, _ = b.correct(P, z, H, r)
    P_i, dx_i, _, _ = ekf_correct_dx(P * 1.4, z, H, r, 1e4, nav.copy(), *args)
    np.testing.assert_allclose(dx_b, dx_i, rtol=1e-10)
    np.testing.assert_allclose(P_b, P_i, rtol=1e-10)
    assert b.counts["adaptive_epochs"] == 1


def test_all_rows_rejected_is_a_skipped_epoch():
    rng = np.random.default_rng(2)
    lay, P, H, r, z, S, nav = _problem(rng)
    z = 10.0 * np.sqrt(S)
    b = _belief(lay, P)
    P1, dx1, _, st = b.correct(P, z, H, r)
    assert st == ABSURD and not dx1.any() and b.counts["robust_epochs_all_rejected"] == 1


def test_robust_ekf_under_p1_gross_errors(tmp_path):
    """The first 100 s of P1-sim1 (2.5 m gross errors on every pseudorange every
    20 epochs, 8 sigma): the robust EKF rejects most gross rows, counts them in
    metrics.json, and its horizontal error stays below the EKF's."""
    from typer.testing import CliRunner

    from mixnav.cli import app
    text, _ = resolve("P1-sim1")
    head, rest = text.split("[[methods]]", 1)
    blocks = ["[[methods]]" + b for b in rest.split("[[methods]]")]
    keep = [b for b in blocks if 'name = "ekf"' in b or 'name = "robust"' in b]
    head = head.replace('{ type = "accelerate", duration = "15 s", acceleration = "-0.5 m/s^2" },\n', "")
    head = head.split("segments = [")[0] + 'segments = [\n  { type = "uniform", duration = "50 s" },\n' \
        '  { type = "accelerate", duration = "10 s", acceleration = "1 m/s^2" },\n' \
        '  { type = "turn", duration = "20 s", angle = "90 deg" },\n  { type = "uniform", duration = "20 s" },\n]\n' \
        + "[imu]" + head.split("[imu]", 1)[1]
    p = tmp_path / "p1-short.toml"
    p.write_text(head + "".join(keep))
    res = CliRunner().invoke(app, ["run", str(p), "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())["methods"]
    rob, ekf = m["robust"], m["ekf"]
    gross_epochs = 100 // 20
    assert rob["recoveries"]["robust_rows_rejected"] >= 3 * gross_epochs   # several satellites per gross epoch
    assert ekf["recoveries"]["rejected_absurd"] == 0
    assert rob["horizontal_rmse_m"] < ekf["horizontal_rmse_m"]
    assert np.isfinite(rob["horizontal_max_m"])
