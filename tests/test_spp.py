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


def _constellation(n=8, seed=3):
    """n satellites 20200 km above the receiver at elevations 15..80 deg, spread in azimuth."""
    rng = np.random.default_rng(seed)
    el = np.deg2rad(np.linspace(15, 80, n))
    az = np.deg2rad(np.arange(n) * 360.0 / n + 10)
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
