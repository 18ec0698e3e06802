"""compute_metrics against closed-form answers, and its refusals."""

import json

import numpy as np
import pandas as pd
import pytest

from mixnav.experiment.metrics import METRIC_KEYS_DOC, compute_metrics

ERR_COLS = ["err_n_m", "err_e_m", "err_d_m", "err_vn_mps", "err_ve_mps", "err_vd_mps",
            "err_roll_deg", "err_pitch_deg", "err_yaw_deg"]


def table(n=101, dt=1.0, **cols):
    """A solution table with zero errors except the columns given."""
    d = {"time_s": np.arange(n) * dt}
    for c in ERR_COLS:
        d[c] = np.zeros(n)
    for k, v in cols.items():
        d[k] = np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()
    return pd.DataFrame(d)


def test_constant_3_4_error_gives_5m_horizontal():
    m = compute_metrics(table(err_n_m=3.0, err_e_m=4.0))
    assert m["horizontal_rmse_m"] == pytest.approx(5.0, abs=1e-12)
    assert m["horizontal_max_m"] == pytest.approx(5.0, abs=1e-12)
    assert m["horizontal_p95_m"] == pytest.approx(5.0, abs=1e-12)
    assert m["vertical_rmse_m"] == 0.0 and m["velocity_max_mps"] == 0.0
    assert m["n_epochs"] == 101


def test_sinusoid_over_whole_periods_has_rms_a_over_sqrt2():
    a, period, n_periods, n = 2.5, 10.0, 7, 7000
    t = np.arange(n) * (n_periods * period / n)  # whole periods, end point excluded
    df = table(n=n, err_d_m=a * np.sin(2 * np.pi * t / period), err_roll_deg=a * np.sin(2 * np.pi * t / period))
    df["time_s"] = t
    m = compute_metrics(df)
    assert m["vertical_rmse_m"] == pytest.approx(a / np.sqrt(2), abs=1e-3)
    assert m["roll_rmse_deg"] == pytest.approx(a / np.sqrt(2), abs=1e-3)
    assert m["vertical_max_m"] == pytest.approx(a, abs=1e-3)


def test_vertical_uses_absolute_error():
    m = compute_metrics(table(n=4, err_d_m=[-3.0, 1.0, -1.0, 1.0]))
    assert m["vertical_max_m"] == 3.0
    assert m["vertical_rmse_m"] == pytest.approx(np.sqrt(12 / 4))


def test_velocity_error_is_3d_norm():
    m = compute_metrics(table(err_vn_mps=1.0, err_ve_mps=-2.0, err_vd_mps=2.0))
    assert m["velocity_rmse_mps"] == pytest.approx(3.0)
    assert m["velocity_max_mps"] == pytest.approx(3.0)


def test_yaw_errors_signed_and_near_wrap():
    # wrapped errors near +-180 must count as large, and signs must not cancel
    m = compute_metrics(table(n=4, err_yaw_deg=[-179.5, 2.0, -2.0, 0.5], err_pitch_deg=[1, -1, 1, -1]))
    assert m["yaw_max_deg"] == 179.5
    assert m["yaw_rmse_deg"] == pytest.approx(np.sqrt((179.5**2 + 4 + 4 + 0.25) / 4))
    assert m["pitch_rmse_deg"] == pytest.approx(1.0) and m["pitch_max_deg"] == 1.0
    assert m["roll_max_deg"] == 0.0


def test_p95_of_a_ramp():
    m = compute_metrics(table(n=101, err_e_m=np.arange(101.0)))
    assert m["horizontal_p95_m"] == pytest.approx(95.0)
    assert m["horizontal_max_m"] == 100.0


def test_outage_windows_pick_their_rows():
    # horizontal error = time, vertical error = 2 * time, one row per second 0..100
    t = np.arange(101.0)
    df = table(err_n_m=t, err_d_m=-2 * t)
    m = compute_metrics(df, outages=[(10.0, 20.0), (30.5, 39.5)])
    o1, o2 = m["outages"]
    assert (o1["start_s"], o1["end_s"]) == (10.0, 20.0)
    assert o1["horizontal_max_m"] == 20.0  # the end point is inside
    assert o1["vertical_max_m"] == 40.0
    assert o1["horizontal_final_m"] == 20.0
    assert o2["horizontal_max_m"] == 39.0 and o2["horizontal_final_m"] == 39.0
    assert o2["vertical_max_m"] == 78.0
    # an error peaking inside the window: max and final differ
    df2 = table(n=11, err_e_m=[0, 0, 1, 5, 2, 0, 0, 0, 0, 0, 0])
    (o,) = compute_metrics(df2, outages=[(2.0, 4.0)])["outages"]
    assert o["horizontal_max_m"] == 5.0 and o["horizontal_final_m"] == 2.0
    assert compute_metrics(df)["outages"] == []


def test_empty_outage_window_is_refused_by_name():
    with pytest.raises(ValueError, match=r"\[10\.2, 10\.8\]"):
        compute_metrics(table(), outages=[(10.2, 10.8)])


@pytest.mark.parametrize("col", ["time_s", "err_e_m", "err_vd_mps", "err_yaw_deg"])
def test_missing_column_is_named(col):
    with pytest.raises(ValueError, match=col):
        compute_metrics(table().drop(columns=col))


@pytest.mark.parametrize("col", ["err_n_m", "err_pitch_deg"])
def test_nan_column_is_named(col):
    df = table(nees_pos=3.0)
    df.loc[7, col] = np.nan
    with pytest.raises(ValueError, match=col):
        compute_metrics(df)


def test_nan_nees_is_counted_not_raised():
    """A NaN NEES means the filter's covariance was singular there (run.nees): counted in
    nees_singular_epochs and left out of the mean, unlike a NaN error, which is a fault."""
    df = table(n=4, nees_pos=[1.0, 2.0, np.nan, 6.0])
    m = compute_metrics(df)
    assert m["nees_singular_epochs"] == 1 and m["nees_pos_mean"] == pytest.approx(3.0)
    # epochs where either block was declined, each once: the union, not the larger count
    m = compute_metrics(table(n=4, nees_pos=[1.0, 2.0, np.nan, 6.0], nees_vel=[np.nan, 3.0, np.nan, 3.0]))
    assert m["nees_singular_epochs"] == 2 and m["nees_vel_mean"] == pytest.approx(3.0)


def test_nees_means_only_when_columns_exist():
    assert "nees_pos_mean" not in compute_metrics(table())
    m = compute_metrics(table(n=4, nees_pos=[1.0, 2.0, 3.0, 6.0], nees_vel=3.0))
    assert m["nees_pos_mean"] == pytest.approx(3.0) and m["nees_vel_mean"] == pytest.approx(3.0)


def test_values_are_plain_documented_and_json_ready():
    m = compute_metrics(table(err_n_m=1.0, nees_pos=3.0, nees_vel=3.0), outages=[(5, 6)])
    assert set(m) <= set(METRIC_KEYS_DOC)
    for k, v in m.items():
        if k == "outages":
            assert all(type(x) is float for o in v for x in o.values())
        elif k == "n_epochs":
            assert type(v) is int
        else:
            assert type(v) is float, k
    json.dumps(m, allow_nan=False)


def test_empty_table_is_refused():
    with pytest.raises(ValueError, match="empty"):
        compute_metrics(table(n=0))


def test_a_reference_without_velocity_and_attitude_scores_position_only():
    df = table().drop(columns=["err_vn_mps", "err_ve_mps", "err_vd_mps",
                               "err_roll_deg", "err_pitch_deg", "err_yaw_deg"])
    m = compute_metrics(df)
    assert "horizontal_rmse_m" in m and "velocity_rmse_mps" not in m and "yaw_rmse_deg" not in m


def test_rmse_outside_the_outages():
    df = table()
    t = df["time_s"].to_numpy()
    df["err_n_m"] = np.where((t >= 2.0) & (t <= 4.0), 10.0, 1.0)
    df["err_e_m"] = 0.0
    m = compute_metrics(df, outages=[(2.0, 4.0)])
    assert m["horizontal_rmse_outside_outages_m"] == pytest.approx(1.0)
    assert m["outages"][0]["horizontal_max_m"] == pytest.approx(10.0)


def test_percentiles_of_a_uniform_ramp():
    # |error| = 0, 1, ..., 100 (signs alternate): numpy's linear 95th percentile is 95 exactly
    n = 101
    e = np.arange(n, dtype=float) * np.where(np.arange(n) % 2, -1.0, 1.0)
    m = compute_metrics(table(n=n, err_d_m=e, err_pitch_deg=e, err_vn_mps=e))
    assert m["vertical_p95_m"] == pytest.approx(95.0)
    assert m["pitch_p95_deg"] == pytest.approx(95.0)
    assert m["velocity_p95_mps"] == pytest.approx(95.0)
    assert m["roll_p95_deg"] == 0.0


def test_a_singular_covariance_gives_a_counted_nan_nees_not_an_error():
    """An epoch whose position covariance is singular (a collapsed particle cloud): its NEES
    is NaN in the solution table, the means leave it out, and the metrics count it; the
    other epochs' NEES equal a direct solve."""
    from mixnav.config.loader import load_scenario
    from mixnav.experiment.run import method_metrics, run_scenario, solution_table
    sc, src, _ = load_scenario("loose-demo")
    out = run_scenario(sc, src, seed=1)
    res = out.results["ekf"]
    res.pv_cov[5] = 0.0                                   # singular
    t = solution_table(res, out.sim.truth, out.sim.outages)
    assert np.isnan(t.nees_pos[5]) and np.isnan(t.nees_vel[5]) and np.isnan(t.nees_pv[5])
    e = t[["err_n_m", "err_e_m", "err_d_m"]].to_numpy()[6]
    assert t.nees_pos[6] == pytest.approx(e @ np.linalg.solve(res.pv_cov[6, 3:, 3:], e), rel=1e-10)
    m = method_metrics(res, t, out.sim.outages)
    assert m["nees_singular_epochs"] == 1
    assert m["nees_pos_mean"] == pytest.approx(np.nanmean(t.nees_pos), rel=1e-12)


def _exact_nees(e, C):
    """e^T C^-1 e in exact rational arithmetic (Gauss-Jordan on Fractions): the reference."""
    from fractions import Fraction
    d = len(e)
    A = [[Fraction(float(C[i, j])) for j in range(d)] + [Fraction(float(e[i]))] for i in range(d)]
    for c in range(d):
        p = next(r for r in range(c, d) if A[r][c] != 0)
        A[c], A[p] = A[p], A[c]
        for r in range(d):
            if r != c and A[r][c] != 0:
                f = A[r][c] / A[c][c]
                A[r] = [a - f * b for a, b in zip(A[r], A[c])]
    return float(sum(Fraction(float(e[i])) * A[i][d] / A[i][i] for i in range(d)))


def test_nees_is_undefined_where_the_covariance_is_singular_or_nearly():
    """run.nees: the closed form on well-conditioned covariances; NaN (counted, never a
    negative or astronomic number) where the covariance is not finite, not positive definite,
    or positive definite with a correlation matrix too ill-conditioned (NEES_CONDITION_LIMIT;
    P3's lost PF runs had a plain-solve NEES mean of -6e129). Each epoch is judged alone,
    and axes in very different units are not taken for near-singularity."""
    from mixnav.experiment.run import NEES_CONDITION_LIMIT, nees
    rng = np.random.default_rng(3)
    K, d = 200, 6
    A = rng.standard_normal((K, d, d))
    C = A @ A.transpose(0, 2, 1) + 0.1 * np.eye(d)
    e = rng.standard_normal((K, d))
    ref = np.array([e[k] @ np.linalg.solve(C[k], e[k]) for k in range(K)])
    np.testing.assert_allclose(nees(e, C), ref, rtol=1e-9)
    Q, _ = np.linalg.qr(rng.standard_normal((d, d)))
    near = Q @ np.diag([1.0, 1, 1, 1, 1, 1e-13]) @ Q.T        # positive definite, kappa 1e13
    near = (near + near.T) / 2
    np.linalg.cholesky(near)          # factorises: the condition test alone must decline it
    C2 = C.copy()
    C2[7] = near
    out = nees(e, C2)                 # no epoch fails the factorisation in this batch
    assert np.isnan(out[7]) and np.isfinite(np.delete(out, 7)).all()
    v = rng.standard_normal(d)
    bad = {3: np.zeros((d, d)),                                   # singular
           4: np.diag([1.0, 1, 1, 1, 1, -1e-3]),                  # indefinite
           5: 1e4 * np.outer(v, v) + 1e-12 * np.eye(d),           # rank one + round-off
           6: np.full((d, d), np.nan),                            # no covariance at all
           7: near}
    for k, c in bad.items():
        C[k] = c
    out2 = nees(e, C)
    assert np.isnan(out2[list(bad)]).all()
    keep = np.setdiff1d(np.arange(K), list(bad))
    np.testing.assert_allclose(out2[keep], ref[keep], rtol=1e-9)
    assert (out2[keep] >= 0).all()
    # judged alone: the same values whether or not a non-factorisable epoch is in the batch
    np.testing.assert_array_equal(out2[keep], out[keep])
    assert nees(np.zeros((0, d)), np.zeros((0, d, d))).shape == (0,)
    # axes of very different units are not "nearly singular": diag(1e10, 1e-7, 1) is exact
    D = np.diag([1e10, 1e-7, 1.0])
    x = np.array([3e5, 2e-4, 0.5])
    assert nees(x[None], D[None])[0] == pytest.approx(9.0 + 0.4 + 0.25, rel=1e-12)
    assert NEES_CONDITION_LIMIT > 1e6


def test_nees_kept_on_ill_conditioned_covariances_is_accurate():
    """Every NEES that run.nees returns on covariances with eigenvalues spread over 15
    decades and axis scales over 8 (both drawn at random) is within 1e-5 of the exact
    rational value: the condition limit declines before round-off takes over (measured
    worst 1.5e-7, 59 of the 200 draws kept; without the limit the kept values are off by
    1e-3 and more). And covariances scaled into the subnormal range stay exact (the
    correlation matrix is factored, not C: factoring C lost 80 % at a scale of 1e-318)."""
    from mixnav.experiment.run import nees
    rng = np.random.default_rng(1)
    kept = 0
    for _ in range(200):
        d = int(rng.choice([3, 6]))
        Q, _ = np.linalg.qr(rng.standard_normal((d, d)))
        lam = np.exp(rng.uniform(np.log(1e-15), 0.0, d))
        lam[0] = 1.0
        S = np.diag(np.exp(rng.uniform(-9.0, 9.0, d)))
        C = S @ Q @ np.diag(lam) @ Q.T @ S
        C = (C + C.T) / 2
        x = S @ rng.standard_normal(d)
        v = nees(x[None], C[None])[0]
        if np.isfinite(v):
            kept += 1
            assert v == pytest.approx(_exact_nees(x, C), rel=1e-5)
    assert kept >= 25         # the check is not empty
    for scale in (1e300, 1e-300, 1e-318):
        Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
        C = Q @ np.diag([1.0, 0.3, 1e-3]) @ Q.T
        C = (C + C.T) / 2 * scale
        x = rng.standard_normal(3) * np.sqrt(scale)
        assert nees(x[None], C[None])[0] == pytest.approx(_exact_nees(x, C), rel=1e-6), scale
