"""TDCP rows for the GNSS-only (constant-velocity) filters (measurements/tdcp_pseudorange.py):
the Jacobian against finite differences of the prediction, over the current state and the
clone; pairs only across continuous carriers; zero innovation at the truth."""

import numpy as np
import pytest

from mixnav.errors import ArgumentError
from mixnav.geodesy.frames import dcm_ecef_to_ned, lla_to_ecef
from mixnav.gnss.geometry import C_LIGHT, earth_rotation_correction
from mixnav.gnss.pseudoranges import PseudorangeEpochs
from mixnav.measurements.kinds import PSEUDORANGE, TDCP
from mixnav.measurements.tdcp_pseudorange import PseudorangeTdcp
from mixnav.motion._common import move_position
from mixnav.motion.constant_velocity import constant_velocity_layout

LLA0 = np.array([np.radians(22.3), np.radians(114.18), 5.0])


def two_epochs(rng, n_sat=8, systems=(1, 32), offset=7.0, bias=(100.0, 103.0), step=(0.4, -0.3, 0.1)):
    """Satellites 20 000 km away in random directions above the horizon, a receiver that moves
    by ``step`` NED metres between two epochs 1 s apart, clock ``bias``, the second system's
    offset; pseudoranges and carriers [m] (carrier ambiguities per satellite) exact."""
    r0 = lla_to_ecef(LLA0)
    C_ne = dcm_ecef_to_ned(LLA0[0], LLA0[1])
    r1 = r0 + C_ne.T @ np.array(step)
    dirs = rng.standard_normal((n_sat, 3))
    dirs[:, 2] = -np.abs(dirs[:, 2]) - 0.3            # up (NED down negative)
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    sys = np.array([systems[k % len(systems)] for k in range(n_sat)])
    sat_id = np.arange(1, n_sat + 1)
    amb = rng.uniform(-1e5, 1e5, n_sat)
    rows = []
    for e, (r, b) in enumerate(zip((r0, r1), bias)):
        s = r0 + 2.0e7 * (dirs @ C_ne) + e * rng.uniform(-3e3, 3e3, (n_sat, 3))   # satellites move
        tau = np.linalg.norm(s - r, axis=1) / C_LIGHT
        rng_ = np.linalg.norm(earth_rotation_correction(s, tau) - r, axis=1)
        o = np.where(sys == systems[0], 0.0, offset)
        rows.append((np.full(n_sat, float(e)), rng_ + b + o, s, rng_ + b + o + amb))
    t, pr, s, cp = (np.concatenate(c) for c in zip(*rows))
    ep = PseudorangeEpochs.from_rows(t, pr, np.full(len(t), 9.0), s, np.tile(sat_id, 2), np.tile(sys, 2))
    return ep, cp, (r0, r1), C_ne


def nav_at(r_ecef):
    from mixnav.geodesy.frames import ecef_to_lla
    nav = np.zeros(10)
    nav[0] = 1.0
    nav[7:10] = ecef_to_lla(r_ecef)
    return nav


@pytest.fixture
def model():
    rng = np.random.default_rng(5)
    ep, cp, (r0, r1), C_ne = two_epochs(rng)
    lay = constant_velocity_layout(clock=True, system_offsets=1)
    m = PseudorangeTdcp(ep, cp, np.ones(len(cp), bool), lay, systems=(1, 32), sigma_cp=0.003)
    return m, lay, r0, r1


def test_innovation_is_zero_at_the_truth(model):
    m, lay, r0, r1 = model
    mem = m.remember(0, nav_at(r0), np.zeros(3), np.array([100.0, 0.0]), aux={"system_offset": np.array([7.0])})
    rows = m.rows(1, nav_at(r1), np.zeros(3), np.array([103.0, 0.0]), mem, aux={"system_offset": np.array([7.0])})
    n_pr = 8
    assert rows.kinds.tolist() == [PSEUDORANGE] * n_pr + [TDCP] * 8
    np.testing.assert_allclose(rows.z, 0.0, atol=1e-6)
    assert rows.H.shape == (16, lay.n + 5) and not rows.H[:n_pr, lay.n:].any()
    np.testing.assert_allclose(rows.R[n_pr:], 2 * 0.003 ** 2)


def test_jacobian_against_finite_differences(model):
    """``z(x + d) - z(x) = -H d`` for a small step ``d`` in each error state the rows depend
    on: the current NED position, clock bias, offset, and the clone's position, bias, offset."""
    m, lay, r0, r1 = model
    nav1 = nav_at(r1 + np.array([30.0, -20.0, 10.0]))       # away from the truth: a real linearisation
    clock = np.array([95.0, 0.0])
    aux = {"system_offset": np.array([5.0])}
    mem = m.remember(0, nav_at(r0 + np.array([-10.0, 5.0, 3.0])), np.zeros(3), np.array([98.0, 0.0]),
                     aux={"system_offset": np.array([6.0])})
    base = m.rows(1, nav1, np.zeros(3), clock, mem, aux=aux)
    H = base.H
    h = 1e-3
    for col in range(H.shape[1]):
        nav, c, a, mm = nav1.copy(), clock.copy(), {"system_offset": aux["system_offset"].copy()}, mem
        if col in range(lay.pos.start, lay.pos.stop):
            d = np.zeros(3)
            d[col - lay.pos.start] = h
            move_position(nav, *d)
        elif col == lay.clk:
            c[0] += h
        elif col == lay.slice("system_offset").start:
            a["system_offset"][0] += h
        elif col >= lay.n:
            dx_c = np.zeros(m.clone_size)
            dx_c[col - lay.n] = h
            mm = m.correct_memory(mem, dx_c)
        else:
            assert not H[:, col].any(), col           # velocity and drift: no part in these rows
            continue
        z = m.rows(1, nav, np.zeros(3), c, mm, aux=a).z
        np.testing.assert_allclose((z - base.z) / h, -H[:, col], atol=2e-5, err_msg=str(col))


def test_pairs_only_across_continuous_carriers_and_consecutive_epochs(model):
    m, lay, r0, r1 = model
    ep = m.epochs
    cont = np.ones(len(m.carrier), bool)
    cont[ep.rows_of(1)][:0] = False
    cont[ep.start[1] + 2] = False                     # a slip on the third satellite at epoch 1
    cp = m.carrier.copy()
    cp[ep.start[0] + 4] = np.nan                      # no carrier for the fifth at epoch 0
    m2 = PseudorangeTdcp(ep, cp, cont, lay, systems=(1, 32))
    mem = m2.remember(0, nav_at(r0), np.zeros(3), np.array([100.0, 0.0]), aux={"system_offset": np.array([7.0])})
    cur, prev = m2.tdcp_pairs(1, mem)
    assert sorted(ep.sat_id[cur].tolist()) == [1, 2, 4, 6, 7, 8]
    np.testing.assert_array_equal(ep.sat_id[cur], ep.sat_id[prev])
    assert m2.tdcp_pairs(1, mem._replace(i=-1)) is None   # not the previous epoch: no TDCP
    with pytest.raises(ArgumentError):
        PseudorangeTdcp(ep, cp[:-1], cont, lay, systems=(1, 32))


# ------------------------------------------------------------------ seeded consistency


def simulate_cv(rng, n_ep=240, accel=0.3, sigma_pr=3.0, sigma_cp=0.003, q_bias=0.1, q_drift=0.01):
    """A receiver on the constant-velocity model's own process (white acceleration ``accel``
    [m/s^2/sqrt(Hz)], 1 s steps), a clock on the ClockModel's, 9 satellites fixed in ECEF
    20 000 km away above the horizon; pseudoranges and carriers [m] with white noise."""
    from mixnav.geodesy.frames import ecef_to_lla
    C_ne = dcm_ecef_to_ned(LLA0[0], LLA0[1])
    r_origin = lla_to_ecef(LLA0)
    dirs = rng.standard_normal((9, 3))
    dirs[:, 2] = -np.abs(dirs[:, 2]) - 0.3
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    sats = r_origin + 2.0e7 * (dirs @ C_ne)
    amb = rng.uniform(-1e5, 1e5, 9)
    T = 1.0
    Q = accel ** 2 * np.array([[T ** 3 / 3, T ** 2 / 2], [T ** 2 / 2, T]])
    Qc = np.array([[q_bias * T + q_drift * T ** 3 / 3, q_drift * T ** 2 / 2], [q_drift * T ** 2 / 2, q_drift * T]])
    p, v = np.zeros(3), np.array([10.0, 5.0, 0.0])
    clk = np.array([50.0, 0.2])
    truth, rows = [], []
    for k in range(n_ep):
        if k:
            for ax in range(3):
                w = np.linalg.cholesky(Q) @ rng.standard_normal(2)
                p[ax] += v[ax] * T + w[0]
                v[ax] += w[1]
            clk = np.array([clk[0] + clk[1] * T, clk[1]]) + np.linalg.cholesky(Qc) @ rng.standard_normal(2)
        r = r_origin + C_ne.T @ p
        truth.append((ecef_to_lla(r), v.copy(), clk.copy()))
        tau = np.linalg.norm(sats - r, axis=1) / C_LIGHT
        geo = np.linalg.norm(earth_rotation_correction(sats, tau) - r, axis=1)
        rows.append((np.full(9, float(k)), geo + clk[0] + sigma_pr * rng.standard_normal(9),
                     geo + clk[0] + amb + sigma_cp * rng.standard_normal(9)))
    t, pr, cp = (np.concatenate(c) for c in zip(*rows))
    ep = PseudorangeEpochs.from_rows(t, pr, np.full(len(t), sigma_pr ** 2), np.tile(sats, (n_ep, 1)),
                                     np.tile(np.arange(1, 10), n_ep), np.ones(len(t), int))
    return ep, cp, truth


def test_tdcp_keeps_the_constant_velocity_filter_consistent_and_sharpens_velocity():
    """Five seeded runs of the EKF on the constant-velocity model with pseudoranges alone and
    with TDCP (cloned previous position and clock). Both consistent: the mean NEES per dof of
    position and velocity in (0.3, 1.3) (5 x ~240 correlated epochs; TDCP's white-noise
    approximation of successive TDCPs sharing a carrier epoch makes it somewhat conservative,
    as the INS model, tests/test_tdcp.py; measured 1.00 without, 0.74 with); TDCP measures
    each 1 s displacement to millimetres, so the velocity error falls (0.57 -> 0.16 m/s
    measured: what is left is the velocity's change within a step, 0.3 m/s^2/sqrt(Hz) of white
    acceleration, that a displacement averages; asserted 2.5x)."""
    from mixnav.data import InitialState
    from mixnav.engine.engine import Engine
    from mixnav.filters.ekf import KalmanEstimator
    from mixnav.ins.error_model import ClockModel
    from mixnav.measurements.pseudorange import PseudorangeGnss
    from mixnav.motion.constant_velocity import ConstantVelocityMotion, ConstantVelocityNoise, clock_ticks
    from mixnav.geodesy.frames import ned_displacement
    lay = constant_velocity_layout(clock=True)
    out = {"pr": [], "tdcp": []}
    for seed in range(5):
        rng = np.random.default_rng(40 + seed)
        ep, cp, truth = simulate_cv(rng)
        lla = np.array([x[0] for x in truth])
        vel = np.array([x[1] for x in truth])
        sig_p, sig_v = np.full(3, 5.0), np.full(3, 1.0)
        nav0 = np.zeros(10)
        nav0[0] = 1.0
        nav0[7:10] = lla[0]
        move_position(nav0, *(sig_p * rng.standard_normal(3)))
        nav0[4:7] = vel[0] + sig_v * rng.standard_normal(3)
        init = InitialState(time=0.0, nav=nav0, sigma_att=np.zeros(3), sigma_vel=sig_v, sigma_pos=sig_p,
                            sigma_clock=np.array([10.0, 1.0]),
                            clock0=truth[0][2] + np.array([10.0, 1.0]) * rng.standard_normal(2))
        ticks = clock_ticks(0.0, float(ep.time[-1]), 1.0)
        for name, model in (("pr", PseudorangeGnss(ep, lay, systems=(1,))),
                            ("tdcp", PseudorangeTdcp(ep, cp, np.ones(len(cp), bool), lay, systems=(1,)))):
            motion = ConstantVelocityMotion(lay, ConstantVelocityNoise(0.3, 0.3), ClockModel(0.1, 0.01))
            res = Engine(motion, KalmanEstimator(), [model], rng=seed).run(ticks, init, output_times=ep.time[1:])
            k = np.searchsorted(ep.time, res.time)
            d_p = ned_displacement(lla[k], res.nav[:, 7:10])          # truth - estimate, NED
            d_v = vel[k] - res.nav[:, 4:7]
            err = np.hstack([d_v, d_p])
            nees = np.einsum("ki,kij,kj->k", err, np.linalg.inv(res.pv_cov), err) / 6
            out[name].append((nees[20:].mean(), np.sqrt(np.mean(d_v[20:] ** 2))))
    nees = {k: np.mean([x[0] for x in v]) for k, v in out.items()}
    v_rms = {k: np.mean([x[1] for x in v]) for k, v in out.items()}
    print("NEES per dof", nees, "velocity RMS [m/s]", v_rms)
    assert 0.3 < nees["pr"] < 1.3 and 0.3 < nees["tdcp"] < 1.3, nees
    assert v_rms["tdcp"] < v_rms["pr"] / 2.5, v_rms


# ------------------------------------------------------------------ the real carrier

URBANNAV = __import__("pathlib").Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "urbannav-tst-static"


@pytest.mark.slow
@pytest.mark.skipif(not (URBANNAV / "2020_06_03_TST_03.obs").exists(), reason="urbannav data not present")
def test_urbannav_carrier_agrees_with_the_surveyed_point():
    """The F9P's carrier through the filters' path (corrected rows, wavelengths per system and
    GLONASS channel, slips): TDCP less the range change from the surveyed antenna and the
    epoch's clock change is millimetres on every continuous pair of every system (measured
    1.6-3.6 mm robust sigma, max 45 mm: multipath), so no slip of half a cycle (9.5 cm) or
    more is left in them; the pairs the loss-of-lock flag cut carry real slips (most of them
    half a cycle, some metres)."""
    from mixnav.config.loader import load_dataset
    from mixnav.experiment.spp_process import _epoch_times, _systems_of, options, read_raw, solve_raw
    from mixnav.gnss.cycle_slips import REASONS, carrier_of_rows, slips_of_observations, static_tdcp_residuals
    from mixnav.gnss.pseudoranges import SYSTEM_LETTERS
    from mixnav.gnss.spp import clock_jumps, corrected_pseudoranges
    ds, source, _ = load_dataset("urbannav-tst-static")
    ds = ds.model_copy(update={"methods": [m for m in ds.methods if m.name == "spp"]})
    folder = (URBANNAV).resolve()
    obs, eph, _ = read_raw(ds, source, folder)
    tr = solve_raw(ds, source, folder, obs, eph).track
    times = _epoch_times(tr)
    rp = ds.reference_point
    point = lla_to_ecef(np.array([rp.latitude, rp.longitude, rp.height]))
    offset, _, _ = clock_jumps(times, tr.clock_bias, tr.ok, 1000.0)
    rho = obs.pseudorange - offset[obs.epoch]
    system, chan = _systems_of(obs, eph)
    epochs, _ = corrected_pseudoranges(eph, obs.week, obs.tow, obs.epoch, obs.prn, rho,
                                       np.tile(point, (len(times), 1)), options(ds), system=system,
                                       glonass_channel=chan)
    slips = slips_of_observations(obs)
    carrier, cont, src = carrier_of_rows(obs, epochs, rho, np.searchsorted(times, epochs.time - 1e-6), slips)
    rows, _, d = static_tdcp_residuals(epochs, carrier, point, cont)
    letters = np.array([SYSTEM_LETTERS[int(c)] for c in epochs.system[rows]])
    good = cont[rows]
    for s in "GREC":
        v = np.abs(d[good & (letters == s)])
        assert len(v) > 2000
        assert 1.4826 * np.median(v) < 0.005 and v.max() < 0.06, (s, np.median(v), v.max())
    lost = ~good & ((slips.flags[src[rows]] & REASONS["loss of lock"]) != 0)
    assert (np.abs(d[lost]) > 0.07).sum() >= 15    # 19 of the 25 above 9 cm (benchmarks/results/tdcp_urbannav.md)
