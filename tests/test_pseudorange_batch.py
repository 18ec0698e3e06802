"""The multi-system pseudorange model on a batch of members (the ensemble filters' ``h``).

- each member's batch prediction is the model's own single-state prediction at that
  member's full state (position, clock bias, inter-system offset): ``y - Y[j]`` equals
  the innovation ``z`` of :meth:`PseudorangeGnss.rows` there, to round-off;
- the finite-difference Jacobian of the batch prediction over the members' error states
  is the rows' ``H`` (the two halves of the model agree on what each state does);
- the UKF, DD2 and GMPF run on it (constant-velocity model, simulated drive) and land
  where the EKF does; the bootstrap PF runs but does not (an expected failure, explained).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mixnav.data import InitialState
from mixnav.engine.engine import Engine
from mixnav.engine.protocols import Epoch
from mixnav.filters.dd2 import Dd2Estimator
from mixnav.filters.ekf import KalmanEstimator
from mixnav.filters.gmpf import GmpfEstimator
from mixnav.filters.particle import ParticleEstimator
from mixnav.filters.ukf import UnscentedEstimator, predict_members
from mixnav.geodesy.frames import dcm_ecef_to_ned, lla_to_ecef, lla_to_ned, ned_to_lla
from mixnav.gnss.geometry import C_LIGHT, earth_rotation_correction
from mixnav.gnss.pseudoranges import PseudorangeEpochs
from mixnav.measurements.pseudorange import PseudorangeGnss
from mixnav.motion import ConstantVelocityMotion, DeadReckoningMotion, clock_ticks
from mixnav.motion.constant_velocity import ConstantVelocityNoise, constant_velocity_layout
from mixnav.motion.dead_reckoning import dead_reckoning_layout, set_heading

LLA0 = np.array([math.radians(48.1), math.radians(11.6), 520.0])
OFFSET = 37.0        # [m] GLONASS - GPS receiver clock offset of the simulation


def _nav(psi=0.3, speed=8.0, lla=LLA0):
    nav = np.zeros(10)
    set_heading(nav, psi)
    nav[4:6] = speed * math.cos(psi), speed * math.sin(psi)
    nav[7:10] = lla
    return nav


def _sky(seed=2):
    """Seven GPS and six GLONASS satellites fixed in the sky above LLA0 (ECEF, ~20 000 km)."""
    rng = np.random.default_rng(seed)
    C_ne = dcm_ecef_to_ned(LLA0[0], LLA0[1])
    r0 = lla_to_ecef(LLA0)
    sats, systems, ids = [], [], []
    for n_s, code, dist in ((7, 1, 2.02e7), (6, 4, 1.91e7)):
        az = rng.uniform(0, 2 * math.pi, n_s)
        el = rng.uniform(math.radians(15), math.radians(80), n_s)
        u_n = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)], axis=1)
        sats.append(r0 + (u_n @ C_ne) * dist)
        systems += [code] * n_s
        ids += list(range(1, n_s + 1))
    return np.vstack(sats), np.array(systems), np.array(ids)


def _epochs(times, lla, clock_bias, sigma=0.0, seed=0, systems_used=(1, 4)):
    """Pseudoranges of the true positions ``lla`` (K, 3) at ``times``: satellites given at the
    transmit time in that time's ECEF frame, so the model's Earth-rotation turn is exercised."""
    rng = np.random.default_rng(seed)
    sats, systems, ids = _sky()
    keep = np.isin(systems, systems_used)
    sats, systems, ids = sats[keep], systems[keep], ids[keep]
    cols = {k: [] for k in ("t", "pr", "var", "sat", "id", "sys")}
    for t, p, b in zip(times, lla, clock_bias):
        r = lla_to_ecef(p)
        s_tx = earth_rotation_correction(sats, -np.linalg.norm(sats - r, axis=1) / C_LIGHT)
        tau = np.linalg.norm(s_tx - r, axis=1) / C_LIGHT
        rho = np.linalg.norm(earth_rotation_correction(s_tx, tau) - r, axis=1)
        pr = rho + b + OFFSET * (systems == 4) + sigma * rng.standard_normal(len(rho))
        for k, v in (("t", np.full(len(pr), t)), ("pr", pr), ("var", np.full(len(pr), max(sigma, 1.0) ** 2)),
                     ("sat", s_tx), ("id", ids), ("sys", systems)):
            cols[k].append(v)
    c = {k: np.vstack(v) if k == "sat" else np.concatenate(v) for k, v in cols.items()}
    return PseudorangeEpochs.from_rows(c["t"], c["pr"], c["var"], c["sat"], c["id"], c["sys"],
                                       elevation=np.full(len(c["pr"]), 0.6), cn0=np.full(len(c["pr"]), 42.0))


def _setup(kind):
    if kind == "dead-reckoning":
        lay = dead_reckoning_layout(clock=True, system_offsets=1)
        motion = DeadReckoningMotion(lay)
    else:
        lay = constant_velocity_layout(clock=True, system_offsets=1)
        motion = ConstantVelocityMotion(lay)
    ep = _epochs([1.0], [LLA0 + np.array([2e-6, -3e-6, 4.0])], [120.0])
    return lay, motion, PseudorangeGnss(ep, lay, systems=(1, 4))


def _epoch(model, nav, clock, aux):
    return Epoch(1.0, 0, model, nav, np.zeros(3), clock, None, aux)


@pytest.mark.parametrize("kind", ["dead-reckoning", "constant-velocity"])
def test_each_member_is_the_single_state_prediction(kind):
    """Members hundreds of metres, kilometres of clock and tens of metres of offset apart:
    ``y - Y[j]`` is the rows' innovation at member ``j``'s own full state."""
    lay, motion, model = _setup(kind)
    nav, clock, aux = _nav(), np.array([100.0, 1.5]), {"system_offset": np.array([30.0])}
    rng = np.random.default_rng(3)
    N = 30
    D = rng.standard_normal((N, lay.n))
    D[:, lay.pos] *= 300.0
    D[:, lay.clk] *= 2000.0
    D[:, lay.slice("system_offset")] *= 50.0
    D[0] = 0.0
    navs = np.empty((N, 10))
    motion.member_states(nav, np.zeros(12), D, navs)
    y, Y, R = predict_members(_epoch(model, nav, clock, aux), D, navs, lay.clk, "test", motion)
    off = lay.slice("system_offset")
    for j in range(N):
        rows = model.rows(0, navs[j], np.zeros(3), clock + D[j, lay.clk:lay.clk + 2],
                          aux={"system_offset": aux["system_offset"] + D[j, off]})
        np.testing.assert_allclose(y - Y[j], rows.z, rtol=0, atol=1e-6)
        np.testing.assert_array_equal(R, rows.R)
    # the members differ by what they should: the clock moves every row, the offset only GLONASS
    glo = model.row_info(0)["system"] == 4
    assert np.ptp(Y[:, ~glo] - Y[:, [0]], axis=0).max() > 1.0
    d_off = (Y[1:, glo] - Y[0, glo]) - (Y[1:, [0]] - Y[0, 0])    # against a GPS row's change
    assert np.abs(d_off).max() > 10.0


@pytest.mark.parametrize("kind", ["dead-reckoning", "constant-velocity"])
def test_batch_jacobian_is_the_rows_H(kind):
    """Central differences of ``Y`` over members ``+-eps e_k`` (every error state) give ``H``
    (``z = y - h``: ``H = dh/dx``); the heading, velocity, odometer and drift columns vanish."""
    lay, motion, model = _setup(kind)
    nav, clock, aux = _nav(), np.array([100.0, 1.5]), {"system_offset": np.array([30.0])}
    H = model.rows(0, nav, np.zeros(3), clock, aux=aux).H
    eps = 0.05
    D = np.zeros((2 * lay.n, lay.n))
    for k in range(lay.n):
        D[2 * k, k], D[2 * k + 1, k] = eps, -eps
    navs = np.empty((len(D), 10))
    motion.member_states(nav, np.zeros(12), D, navs)
    _, Y, _ = predict_members(_epoch(model, nav, clock, aux), D, navs, lay.clk, "test", motion)
    J = ((Y[0::2] - Y[1::2]) / (2 * eps)).T
    np.testing.assert_allclose(J, H, rtol=0, atol=1e-6)
    assert np.abs(H[:, lay.pos]).max() > 0.5 and (H[:, lay.clk] == 1.0).all()


def test_no_update_below_min_satellites_and_defaults():
    lay = constant_velocity_layout(clock=True)
    ep = _epochs([1.0], [LLA0], [0.0], systems_used=(1,))
    model = PseudorangeGnss(ep, lay, systems=(1,), min_satellites=8)
    assert model.predict_batch(0, _nav()[None], np.zeros(3)) is None
    model = PseudorangeGnss(ep, lay, systems=(1,))
    # one state, no clock given: the geometric ranges (the simulation's truth, no noise)
    y, Y, R = model.predict_batch(0, _nav()[None], np.zeros(3))
    assert Y.shape == (1, 7) and np.abs(y - Y[0]).max() < 1e-6


def _drive(T=60.0, v=6.0, psi=0.7):
    t = np.arange(1.0, T + 1e-9, 1.0)
    ned = np.stack([v * t * math.cos(psi), v * t * math.sin(psi), np.zeros_like(t)], axis=1)
    return t, ned_to_lla(ned, LLA0), psi, v


def _run(estimator, t, lla, psi, v, seed=4):
    lay = constant_velocity_layout(clock=True, system_offsets=1)
    ep = _epochs(t, lla, 80.0 + 1.5 * t, sigma=3.0, seed=seed)
    nav = _nav(psi, 0.0)
    init = InitialState(time=0.0, nav=nav, sigma_att=np.zeros(3), sigma_vel=np.full(3, 10.0),
                        sigma_pos=np.full(3, 10.0), sigma_clock=np.array([300.0, 10.0]))
    motion = ConstantVelocityMotion(lay, ConstantVelocityNoise(0.5, 0.1))
    res = Engine(motion, estimator, [PseudorangeGnss(ep, lay, systems=(1, 4))], rng=seed).run(
        clock_ticks(0.0, t[-1], 0.5), init, output_times=t)
    err = lla_to_ned(res.nav[:, 7:10], LLA0) - lla_to_ned(lla, LLA0)
    return res, float(np.sqrt(np.mean(np.sum(err[10:, :2] ** 2, axis=1))))


def test_ensemble_filters_run_on_pseudoranges_and_match_the_ekf():
    """Constant velocity, GPS + GLONASS with a 37 m offset, 3 m noise: on this nearly linear
    model the UKF and DD2 give the EKF's track to centimetres and its GLONASS offset; the
    GMPF (its Gaussian-mixture proposal) lands within Monte Carlo error of it."""
    t, lla, psi, v = _drive()
    ekf, rms_ekf = _run(KalmanEstimator(), t, lla, psi, v)
    assert rms_ekf < 3.0
    for est in (UnscentedEstimator(), Dd2Estimator()):
        res, rms = _run(est, t, lla, psi, v)
        d = lla_to_ned(res.nav[:, 7:10], LLA0) - lla_to_ned(ekf.nav[:, 7:10], LLA0)
        assert np.abs(d[5:]).max() < 0.05, type(est).__name__
        assert abs(res.estimates["system_offset"][-1, 0] - ekf.estimates["system_offset"][-1, 0]) < 0.05
    res, rms = _run(GmpfEstimator(particles=500), t, lla, psi, v)
    assert rms < 1.2 * rms_ekf + 0.3, (rms, rms_ekf)
    assert abs(res.estimates["system_offset"][-1, 0] - OFFSET) < 1.0


@pytest.mark.xfail(strict=True, reason="the bootstrap PF impoverishes in the clock / vertical / drift subspace "
                   "that pseudoranges leave weakly observed (resampled every epoch; 3000 or 10000 particles "
                   "alike, tens of metres): a known limit of the PF's proposal, not of the batch prediction")
def test_bootstrap_particle_filter_on_pseudoranges():
    t, lla, psi, v = _drive()
    _, rms_ekf = _run(KalmanEstimator(), t, lla, psi, v)
    _, rms = _run(ParticleEstimator(particles=1000), t, lla, psi, v)
    assert rms < 1.5 * rms_ekf + 0.5, (rms, rms_ekf)
