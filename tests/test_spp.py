"""Single-point positioning (gnss/spp.py): closed-form oracle, covariance check, atmosphere models."""

import numpy as np
import pytest

from mixnav.geodesy.frames import lla_to_ecef
from mixnav.gnss.geometry import C_LIGHT, OMEGA_E_GPS, SatelliteStates, elevation_azimuth
from mixnav.gnss.spp import (STATUS_FEW, STATUS_OK, SppOptions, klobuchar, saastamoinen, solve_epochs,
                             wls_position)

LLA = np.array([np.deg2rad(37.422578), np.deg2rad(-122.081678), -28.0])
RX = lla_to_ecef(LLA)
CLOCK = 1234.567  # receiver clock bias [m]


def _constellation(n=8, seed=3, el_deg=None, az_deg=None):
    """n satellites 20200 km above the receiver at elevations 15..80 deg, spread in azimuth
    (or at the given elevations and azimuths)."""
    rng = np.random.default_rng(seed)
    el = np.deg2rad(np.linspace(15, 80, n) if el_deg is None else np.asarray(el_deg, float))
    az = np.deg2rad(np.arange(n) * 360.0 / n + 10 if az_deg is None else np.asarray(az_deg, float))
    lat, lon = LLA[0], LLA[1]
    # unit vectors in NED, then ECEF
    u_n = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    c_en = np.array([[-sl * co, -so, -cl * co], [-sl * so, co, -cl * so], [cl, 0.0, -sl]])
    u_e = u_n @ c_en.T
    # range so that |sat| = 26560 km
    b = RX @ u_e.T
    rho = -b + np.sqrt(b**2 - RX @ RX + 26.56e6**2)
    pos_rx_frame = RX + rho[:, None] * u_e
    clk = rng.uniform(-5e-4, 5e-4, n)
    # the positions above are in the reception frame; the states are given in the
    # transmit frame: rotate back by the travel time (solved by fixed point)
    tau = rho / C_LIGHT
    a = -OMEGA_E_GPS * tau
    c, s = np.cos(a), np.sin(a)
    x, y, z = pos_rx_frame.T
    pos_tx = np.column_stack([c * x + s * y, -s * x + c * y, z])
    return SatelliteStates(np.arange(1, n + 1), pos_tx, np.zeros((n, 3)), clk, np.zeros(n)), pos_rx_frame, el


def _exact_pseudoranges(sats, pos_rx_frame, tropo=False):
    rho = np.linalg.norm(pos_rx_frame - RX, axis=1) + CLOCK - C_LIGHT * sats.clock_bias
    if tropo:
        el, _ = elevation_azimuth(RX, pos_rx_frame)
        rho = rho + saastamoinen(LLA[0], LLA[2], el)
    return rho


def test_exact_pseudoranges_recover_position_and_clock():
    sats, pos_rx, _ = _constellation()
    opts = SppOptions(troposphere=False, ionosphere=False, elevation_mask=0.0)
    sol = wls_position(_exact_pseudoranges(sats, pos_rx), sats, opts)
    assert sol.converged and sol.n_sat == 8
    assert np.linalg.norm(sol.pos_ecef - RX) < 1e-3
    assert sol.clock_bias == pytest.approx(CLOCK, abs=1e-3)
    assert np.abs(sol.residuals).max() < 1e-3


def test_exact_with_troposphere_and_mask():
    sats, pos_rx, el = _constellation()
    opts = SppOptions(troposphere=True, ionosphere=False, elevation_mask=np.deg2rad(20))
    sol = wls_position(_exact_pseudoranges(sats, pos_rx, tropo=True), sats, opts)
    assert np.linalg.norm(sol.pos_ecef - RX) < 1e-3 and sol.clock_bias == pytest.approx(CLOCK, abs=1e-3)
    assert sol.n_rejected_mask == int(np.sum(el < np.deg2rad(20))) and sol.n_sat == 8 - sol.n_rejected_mask
    # without the model the same data give a biased height (the troposphere is ~2.4 m at zenith)
    off = wls_position(_exact_pseudoranges(sats, pos_rx, tropo=True), sats,
                       SppOptions(troposphere=False, ionosphere=False, elevation_mask=np.deg2rad(20)))
    assert np.linalg.norm(off.pos_ecef - RX) > 0.5


def test_dops_are_rotation_invariant_geometry():
    sats, pos_rx, _ = _constellation()
    sol = wls_position(_exact_pseudoranges(sats, pos_rx), sats,
                       SppOptions(troposphere=False, ionosphere=False, elevation_mask=0.0))
    u = (pos_rx - RX) / np.linalg.norm(pos_rx - RX, axis=1)[:, None]
    H = np.column_stack([-u, np.ones(len(u))])
    q = np.linalg.inv(H.T @ H)
    assert sol.dop["pdop"] == pytest.approx(np.sqrt(np.trace(q[:3, :3])), rel=1e-6)
    assert sol.dop["gdop"] == pytest.approx(np.sqrt(np.trace(q)), rel=1e-6)
    assert sol.dop["hdop"] ** 2 + sol.dop["vdop"] ** 2 == pytest.approx(sol.dop["pdop"] ** 2, rel=1e-9)


def test_monte_carlo_covariance_matches_wls_covariance():
    sats, pos_rx, el = _constellation()
    opts = SppOptions(troposphere=False, ionosphere=False, elevation_mask=0.0, sigma_a=2.0, sigma_b=4.0)
    exact = _exact_pseudoranges(sats, pos_rx)
    sigma = np.sqrt(opts.sigma_a**2 + opts.sigma_b**2 / np.sin(el) ** 2)
    rng = np.random.default_rng(2024)
    n_runs = 800
    err = np.empty((n_runs, 4))
    x0 = np.append(RX, CLOCK)
    for k in range(n_runs):
        sol = wls_position(exact + sigma * rng.standard_normal(len(el)), sats, opts, x0=x0)
        err[k] = np.append(sol.pos_ecef - RX, sol.clock_bias - CLOCK)
    cov = sol.cov
    sample = np.cov(err.T)
    # a variance estimated from 800 samples has a relative sd of sqrt(2/800) = 5 %;
    # 20 % is four of them
    assert np.allclose(np.diag(sample) / np.diag(cov), 1.0, atol=0.2)
    # NEES: mean of e^T P^-1 e is 4 (dof) with sd sqrt(8/800) = 0.1; allow 4 sd
    nees = np.einsum("ki,ij,kj->k", err, np.linalg.inv(cov), err)
    assert abs(nees.mean() - 4.0) < 0.4
    assert np.abs(err.mean(0)).max() < 4 * np.sqrt(np.diag(cov).max() / n_runs)


def test_too_few_satellites_single_epoch_raises():
    sats, pos_rx, _ = _constellation(n=3)
    with pytest.raises(ValueError, match="at least 4"):
        wls_position(_exact_pseudoranges(sats, pos_rx), sats)
    sats, pos_rx, _ = _constellation(n=5)
    with pytest.raises(ValueError, match="elevation mask"):
        wls_position(_exact_pseudoranges(sats, pos_rx), sats, SppOptions(elevation_mask=np.deg2rad(60)))
    with pytest.raises(ValueError, match="shape"):
        wls_position(np.zeros(4), sats)


class _FixedEphemeris:
    """An ephemeris stand-in returning fixed states (time-independent)."""

    iono_alpha = iono_beta = None

    def __init__(self, sats):
        self.sats = sats

    def states_and_skips(self, week, tow, prns, apply_tgd=True):
        from mixnav.gnss.ephemeris import EphemerisSkips
        prns = np.asarray(prns)
        has = np.isin(prns, self.sats.prn)
        idx = np.searchsorted(self.sats.prn, prns[has])
        missing = prns[~has]
        return self.sats.select(idx), EphemerisSkips(missing, ("no ephemeris",) * len(missing))

    def states(self, week, tow, prns, apply_tgd=True):
        return self.states_and_skips(week, tow, prns)[0]


def test_solve_epochs_counts_skips():
    sats, pos_rx, _ = _constellation(n=6)
    rho = _exact_pseudoranges(sats, pos_rx)
    # epoch 0: all 6; epoch 1: 3 known + 2 without ephemeris -> too few; epoch 2: all 6
    prn = np.concatenate([sats.prn, [1, 2, 3, 31, 32], sats.prn])
    pr = np.concatenate([rho, rho[:3], [2.1e7, 2.2e7], rho])
    epoch = np.repeat([0, 1, 2], [6, 5, 6])
    track = solve_epochs(_FixedEphemeris(sats), [1903] * 3, [1.0, 2.0, 3.0], epoch, prn, pr,
                         SppOptions(troposphere=False, ionosphere=False, elevation_mask=0.0))
    assert track.status.tolist() == [STATUS_OK, STATUS_FEW, STATUS_OK]
    assert track.status_counts() == {STATUS_OK: 2, STATUS_FEW: 1}
    assert track.skipped_satellites["no ephemeris"] == 2
    assert np.isnan(track.pos_ecef[1]).all()
    assert np.linalg.norm(track.pos_ecef[[0, 2]] - RX, axis=1).max() < 1e-3


def test_saastamoinen_zenith_hydrostatic():
    # dry (humidity 0), sea level, latitude 45 deg: 0.0022768 * 1013.25 hPa = 2.3070 m
    assert saastamoinen(np.deg2rad(45), 0.0, np.array([np.pi / 2]), humidity=0.0)[0] == pytest.approx(2.30697, abs=1e-5)
    wet = saastamoinen(np.deg2rad(45), 0.0, np.array([np.pi / 2]), humidity=0.5)[0] - 2.30697
    assert 0.05 < wet < 0.15
    z30 = saastamoinen(0.3, 100.0, np.array([np.pi / 2, np.pi / 6]))
    assert z30[1] == pytest.approx(2 * z30[0])            # 1/sin(el) mapping


def test_klobuchar_night_and_peak():
    el = np.array([np.pi / 2])
    az = np.array([0.0])
    f_zenith = 1.0 + 16.0 * (0.53 - 0.5) ** 3
    alpha, beta = np.array([1e-8, 0, 0, 0]), np.array([72000.0, 0, 0, 0])
    # receiver on the equator at the longitude where the local time equals GPS time;
    # at zenith the pierce point is (almost) the receiver
    lat, lon = 0.0, 0.0
    night = klobuchar(lat, lon, el, az, 0.0, alpha, beta)[0]
    assert night == pytest.approx(C_LIGHT * 5e-9 * f_zenith, rel=1e-12)
    peak = klobuchar(lat, lon, el, az, 50400.0, alpha, beta)[0]     # 14:00 local time
    assert peak == pytest.approx(C_LIGHT * f_zenith * (5e-9 + 1e-8), rel=1e-12)
    # a negative amplitude polynomial is clipped to zero: night value all day
    assert klobuchar(lat, lon, el, az, 50400.0, -alpha, beta)[0] == pytest.approx(night)


# ---------------------------------------------------------------- robust solution
def _noisy(n, seed, opts):
    """n satellites, pseudoranges with the options' elevation-dependent noise (seeded)."""
    sats, pos_rx, el = _constellation(n, seed)
    sigma = np.sqrt(opts.sigma_a**2 + opts.sigma_b**2 / np.sin(el) ** 2)
    rho = _exact_pseudoranges(sats, pos_rx) + np.random.default_rng(seed).normal(0.0, sigma)
    return sats, rho


ROBUST = SppOptions(troposphere=False, ionosphere=False, elevation_mask=0.0, sigma_a=1.0, sigma_b=1.0,
                    robust=(2.5, 5.0))
PLAIN = SppOptions(troposphere=False, ionosphere=False, elevation_mask=0.0, sigma_a=1.0, sigma_b=1.0)


@pytest.mark.parametrize("bad", [0, 4, 9])
def test_robust_solution_excludes_a_gross_error_exactly(bad):
    """12 satellites, 80 m on one: the robust solution leaves that row out (weight zero) and
    is then exactly the WLS solution of the other 11 (1e-6 m); plain WLS is metres off."""
    sats, rho = _noisy(12, 7, PLAIN)
    rho = rho.copy()
    rho[bad] += 80.0
    sol = wls_position(rho, sats, ROBUST)
    assert sol.robust_status == "ok" and sol.n_excluded == 1 and sol.n_downweighted == 0
    assert bad + 1 not in sol.prn
    keep = np.arange(12) != bad
    others = SatelliteStates(sats.prn[keep], sats.pos_ecef[keep], sats.vel_ecef[keep], sats.clock_bias[keep],
                             sats.clock_drift[keep])
    ref = wls_position(rho[keep], others, PLAIN)
    np.testing.assert_allclose(sol.pos_ecef, ref.pos_ecef, atol=1e-6)
    np.testing.assert_allclose(sol.cov, ref.cov, rtol=1e-9)
    plain = wls_position(rho, sats, PLAIN)
    assert np.linalg.norm(plain.pos_ecef - RX) > 3.0 * np.linalg.norm(sol.pos_ecef - RX)


def test_robust_solution_is_plain_wls_without_outliers_and_when_untestable():
    """No residual beyond k0: bitwise the WLS solution. Five satellites (one spare): a single
    error cannot be located, so plain WLS, said by the status."""
    sats, rho = _noisy(10, 11, PLAIN)
    sol, plain = wls_position(rho, sats, ROBUST), wls_position(rho, sats, PLAIN)
    assert sol.robust_status == "ok" and sol.n_excluded == sol.n_downweighted == 0
    np.testing.assert_array_equal(sol.pos_ecef, plain.pos_ecef)
    sats5, rho5 = _noisy(5, 11, PLAIN)
    rho5 = rho5 + np.array([80.0, 0, 0, 0, 0])
    sol5 = wls_position(rho5, sats5, ROBUST)
    assert sol5.robust_status == "untestable"
    np.testing.assert_array_equal(sol5.pos_ecef, wls_position(rho5, sats5, PLAIN).pos_ecef)


def test_robust_solution_declines_rows_it_cannot_tell_apart():
    """Seven satellites (exact ranges) where the residual of the one at 75 deg elevation
    moves with those at 45 and 60 deg (correlations 0.97, -0.97): 80 m on it is not blamed on
    any row (status ``not_separable``, the plain solution kept: bitwise), since the data
    cannot say which of the three is wrong; 80 m on the satellite at 30 deg (largest
    correlation 0.955, with the satellite at 15 deg) is found, and the solution is exact."""
    el, az = [15, 30, 45, 60, 75, 40, 42], [0, 70, 140, 210, 280, 100, 100]
    sats, pos_rx, _ = _constellation(7, 3, el, az)
    exact = _exact_pseudoranges(sats, pos_rx)
    rho = exact + 80.0 * (np.arange(7) == 4)
    sol = wls_position(rho, sats, ROBUST)
    assert sol.robust_status == "not_separable" and sol.n_excluded == 0
    np.testing.assert_array_equal(sol.pos_ecef, wls_position(rho, sats, PLAIN).pos_ecef)
    sol = wls_position(exact + 80.0 * (np.arange(7) == 1), sats, ROBUST)
    assert sol.robust_status == "ok" and sol.n_excluded == 1 and 2 not in sol.prn
    assert np.linalg.norm(sol.pos_ecef - RX) < 1e-3


def test_robust_thresholds_are_checked():
    with pytest.raises(ValueError, match="k0 < k1"):
        SppOptions(robust=(5.0, 2.5))


def test_robust_solution_over_many_geometries():
    """200 seeded epochs, 9 satellites each (random geometry and noise): with 60 m on one
    random satellite per epoch the robust 3-D RMSE is below 0.4 of plain WLS's (measured
    0.21; 27 of the 200 errors fall on rows the geometry cannot separate, kept as plain WLS);
    without it, the false alarms at k0 = 2.5 cost at most 5 % of RMSE (measured 1.000)."""
    rng = np.random.default_rng(0)
    err = {"plain": [], "robust": [], "plain_clean": [], "robust_clean": []}
    for seed in range(200):
        sats, rho = _noisy(9, 1000 + seed, PLAIN)
        for tag, r in (("", rho + 60.0 * (np.arange(9) == rng.integers(9))), ("_clean", rho)):
            err["plain" + tag].append(np.linalg.norm(wls_position(r, sats, PLAIN).pos_ecef - RX))
            err["robust" + tag].append(np.linalg.norm(wls_position(r, sats, ROBUST).pos_ecef - RX))
    rms = {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in err.items()}
    assert rms["robust"] < 0.4 * rms["plain"], rms
    assert rms["robust_clean"] < 1.05 * rms["plain_clean"], rms
