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
