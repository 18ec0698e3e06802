"""The shipped P2 scenarios (paper P2 section 2.1): one setting, three noise cases.

The files are checked against each other and against what their GMEKF is told
(the told mixtures must be the simulated innovation mixtures), and one
simulated run of P2-s2 against P2's epoch-level coloured process noise.
"""

import numpy as np
import pytest

from mixnav.config.loader import imu_white_noise, load_scenario, observable_noise, sweep_variants
from mixnav.noise.processes import AR1, Mixture

SWEEP = [0.0, 0.2, 0.4, 0.6, 0.8, 0.9, 0.95]


@pytest.fixture(scope="module")
def cases():
    out = {}
    for name in ("P2-s1", "P2-s2"):
        sc, src, _ = load_scenario(name)
        out[name] = (sc, src)
    sc, src, text = load_scenario("P2-s3")
    for v, variant in sweep_variants(sc, text, src):
        out[v] = (variant, src)
    return out


def _noise(sc, src):
    """(coefficient or None, innovation mixture) of the IMU, pseudorange, range-rate noise."""
    pr, rr, _ = observable_noise(sc, src)
    out = []
    for p in (imu_white_noise(sc, src), pr, rr):
        if isinstance(p, AR1):
            out.append((float(p.coefficient), p.innovation))
        else:
            out.append((None, p))
    return out


def _methods_but_m6_coefficients(sc):
    return [m.model_dump(exclude={"mixture": {"colored"}}) if m.name in ("m6", "m6-sf") else m.model_dump()
            for m in sc.methods]


def test_the_cases_differ_only_in_the_colour(cases):
    s2 = cases["P2-s2"][0]
    assert [v for v in cases if not isinstance(v, str)] == SWEEP
    for key, (sc, _) in cases.items():
        for part in ("trajectory", "init"):
            assert getattr(sc, part) == getattr(s2, part), (key, part)
        assert _methods_but_m6_coefficients(sc) == _methods_but_m6_coefficients(s2), key
        # M6 is told the case's coefficients (0 in the white case)
        psi = 0.0 if key == "P2-s1" else 0.9 if key == "P2-s2" else key
        for name in ("m6", "m6-sf"):
            c = {m.name: m for m in sc.methods}[name].mixture.colored
            assert c.process == psi and c.measurement == {"pseudorange": psi, "range_rate": psi}, (key, name)
        assert sc.imu.errors == s2.imu.errors and sc.imu.white_noise_hold == 1.0
        g, g2 = sc.gnss.model_dump(), s2.gnss.model_dump()
        for k in ("pseudorange_noise", "range_rate_noise"):
            g["satellites"].pop(k), g2["satellites"].pop(k)
        assert g == g2, key
    # P2-s3 at 0.9 is P2-s2
    assert cases[0.9][0].imu == s2.imu and cases[0.9][0].gnss == s2.gnss
    assert [c for c, _ in _noise(*cases["P2-s1"])] == [None] * 3
    for v in SWEEP:
        assert [c for c, _ in _noise(*cases[v])] == [v] * 3
    assert [c for c, _ in _noise(*cases["P2-s2"])] == [0.9] * 3


def test_the_gmekf_is_told_the_simulated_innovation_mixtures(cases):
    for key, (sc, src) in cases.items():
        (_, w_imu), (_, w_pr), (_, w_rr) = _noise(sc, src)
        assert all(isinstance(m, Mixture) for m in (w_imu, w_pr, w_rr))
        sat = sc.gnss.satellites
        told = {m.name: m for m in sc.methods}["gmekf"].mixture
        # the IMU multiplier is relative to the datasheet density the filter's Q uses
        np.testing.assert_allclose(told.process.weights, w_imu.weights)
        np.testing.assert_allclose(told.process.scales, np.asarray(w_imu.sigmas) ** 2, rtol=1e-7)
        for kind, mix, sigma in (("pseudorange", w_pr, sat.pseudorange_sigma),
                                 ("range_rate", w_rr, sat.range_rate_sigma)):
            np.testing.assert_allclose(told.measurement[kind].weights, mix.weights)
            np.testing.assert_allclose(told.measurement[kind].scales,
                                       (np.asarray(mix.sigmas) / sigma) ** 2, rtol=1e-7)
        # P2 section 2.1: 0.1 N(0, 0.05^2) + 0.9 N(0, 0.2^2), the 0.9 component the datasheet
        # density; 0.1 N(0, 0.3^2) + 0.9 N(0, 0.3^2 / 3) on pseudoranges and range rates
        np.testing.assert_allclose(np.asarray(w_imu.sigmas) * 0.2, [0.05, 0.2])
        np.testing.assert_allclose(np.asarray(w_pr.sigmas) ** 2, [0.09, 0.03], rtol=1e-7)
        np.testing.assert_allclose(np.asarray(w_rr.sigmas) ** 2, [0.09, 0.03], rtol=1e-7)


def test_p2_s2_process_noise_is_coloured_at_the_gnss_epoch(cases):
    # The IMU white noise of one run of P2-s2, recovered from the measured increments: one
    # rate per 1 s interval ending at a GNSS epoch, and epoch sums that are the AR(1) of
    # coefficient 0.9 (P2 eq. 6). Per channel 409 pairs: se sqrt(0.19 / 409) = 0.022 and a
    # least-squares bias of about -(1 + 3 psi) / n = -0.009; the mean over 6 channels has
    # se 0.009, so 0.05 is over 4 se beyond the bias.
    from mixnav.ins.imu_model import hold_intervals
    from mixnav.noise.ar import fit_ar1
    from mixnav.sim.scenario import simulate
    sc, src = cases["P2-s2"]
    run = simulate(sc, 0, src)
    ideal, imu, d = run.imu_ideal, run.imu, run.imu_draw
    k, ends, length = hold_intervals(ideal, 1.0)
    assert np.all(np.isin(np.round(run.observations.time, 6), np.round(ends, 6)))
    dt = ideal.dt[:, None]
    sums = []
    for got, ideal_inc, scale, bias, s in (
            (imu.dtheta, ideal.dtheta, d.gyro_scale, d.gyro_bias, run.imu_model.arw),
            (imu.dvel, ideal.dvel, d.accel_scale, d.accel_bias, run.imu_model.vrw)):
        rate = (got - (1 + scale) * ideal_inc - bias * dt) / dt / s
        first = np.searchsorted(k, np.arange(len(ends)))
        np.testing.assert_allclose(rate, rate[first][k], rtol=1e-6, atol=1e-9 * np.abs(rate).max())
        sums.append(rate[first])        # held rate x sqrt(T) / T = x_k at T = 1 s
    fit = fit_ar1(np.concatenate(sums, axis=1))
    assert fit.psi.mean() == pytest.approx(0.9, abs=0.05)
