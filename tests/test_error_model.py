"""The INS error-state model against finite differences of the mechanization.

The oracle is the nonlinear mechanization itself: propagate a nominal
("estimated") and a perturbed ("true") state with the same measured
increments over one second of a turning, climbing, accelerating drive; the
difference, in error-state coordinates, must match ``Phi @ dx0``. This checks
every sign and coupling of F, including the sensor-error columns.
"""

import numpy as np
import pytest

from mixnav.attitude import attitude_error, quat_multiply, rotvec_to_quat
from mixnav.geodesy import earth
from mixnav.geodesy.frames import ned_displacement
from mixnav.ins._error_kernels import propagate_block
from mixnav.ins.error_model import LAYOUTS
from mixnav.sim.trajectory import InitialState, MotionSegment, generate


def _motion():
    d = np.deg2rad
    segs = [MotionSegment("turn", 2.0, acceleration=0.8, yaw_rate=d(15.0), pitch_rate=d(2.0),
                          roll_rate=d(3.0))]
    return generate(segs, InitialState((d(34.4), d(113.5), 300.0), 20.0, (d(2), d(3), d(40))), 100.0)


def _perturb(nav, dx, lay):
    """The 'true' state for an error ``dx = x_true - x_est`` of ``nav``."""
    t = nav.copy()
    t[0:4] = quat_multiply(rotvec_to_quat(dx[lay.att]), nav[0:4])
    t[4:7] += dx[lay.vel]
    rm, rn = earth.radii(nav[7])
    t[7] += dx[6] / (rm + nav[9])
    t[8] += dx[7] / ((rn + nav[9]) * np.cos(nav[7]))
    t[9] -= dx[8]
    return t


def _error(est, true):
    return np.concatenate([attitude_error(est[0:4], true[0:4]), true[4:7] - est[4:7],
                           ned_displacement(true[7:10], est[7:10])])


@pytest.mark.parametrize("n_states", [15, 21])
@pytest.mark.parametrize("T", [0.25, 0.5, 1.0])
def test_phi_matches_finite_differences(n_states, T):
    lay = LAYOUTS[n_states]
    truth, imu = _motion()
    k = int(round(T * 100))
    nav0 = np.concatenate([truth.q_nb[0], truth.v_n[0], truth.lla[0]])
    args = (imu.dtheta[:k], imu.dvel[:k], imu.dt[:k])
    qc = np.zeros(lay.n)
    tau = np.full(4, np.inf)
    work = np.empty((4, lay.n, lay.n))
    P = np.eye(lay.n)
    nom = nav0.copy()
    propagate_block(nom, np.zeros(6), np.zeros(12), *args, P, qc, lay.as_array(), tau, work, np.zeros(6))
    phi = work[1]  # transition over the block, left in the scratch space

    # perturbation sizes: small enough to stay linear, large enough to beat round-off
    eps = np.concatenate([np.full(3, 1e-5), np.full(3, 1e-3), np.full(3, 1e-1),
                          np.full(3, 1e-6), np.full(3, 1e-4), np.full(n_states - 15, 1e-4)])
    worst_nav = worst_sensor = 0.0
    for j in range(lay.n):
        dx0 = np.zeros(lay.n)
        dx0[j] = eps[j]
        true0 = _perturb(nav0, dx0, lay) if j < 9 else nav0.copy()
        sensor = np.zeros(12)
        # The true IMU has bias/scale larger by dx than the estimate assumes:
        # compensating with the estimate (zero) leaves dx in the true path, so
        # the true path is the nominal one compensated by -dx.
        if j >= 9:
            sensor_map = {lay.bg.start: 0, lay.ba.start: 3, lay.sg: 6, lay.sa: 9}
            base = max(s for s in sensor_map if 0 <= s <= j)
            sensor[sensor_map[base] + (j - base)] = eps[j]
        tr = true0.copy()
        propagate_block(tr, np.zeros(6), sensor, *args, np.empty((0, 0)), qc, lay.as_array(), tau, work, np.zeros(6))
        num = _error(nom, tr) / eps[j]
        pred = phi[:9, j]
        scale = np.abs(pred).max() + 1e-12
        rel = np.abs(num - pred).max() / scale
        if j < 9:
            worst_nav = max(worst_nav, rel)
        else:
            worst_sensor = max(worst_sensor, rel)
    # F is frozen over the step (linearised at its end, with averaged
    # specific force and attitude), so the navigation columns carry an error
    # of second order in T (measured 0.14 %, 0.6 %, 2.5 % at T = 0.25, 0.5,
    # 1 s) and the sensor columns one of first order in the angle turned
    # over the step, because averaging C and f_n separately drops their
    # correlation (measured 2-9 % for 4-15 deg). A wrong sign or a missing
    # coupling misses by 100 % of a column.
    turned = np.linalg.norm(np.deg2rad([3.0, 2.0, 15.0])) * T
    assert worst_nav < 0.03 * T ** 2 + 2e-3
    assert worst_sensor < 0.5 * turned


# --------------------------------------------------------------------------
# P2's 18-state quaternion-error model is the 17-state model mapped by T(q)
# (docs/error_model.md, "The 18-state quaternion model")
# --------------------------------------------------------------------------
def _quat_error_map(q):
    """T(q) (4, 3): additive quaternion error dq = T(q) phi to first order, for
    q_true = q(phi) * q_est (Hamilton, scalar first), the derivation in the docs."""
    from mixnav.attitude import skew
    w, v = q[0], q[1:]
    return 0.5 * np.vstack([-v[None, :], w * np.eye(3) - skew(v)])


def test_18_state_quaternion_update_equals_the_17_state_one():
    from mixnav.attitude import quat_to_rotvec
    from mixnav.geodesy.frames import displace
    from mixnav.gnss.constellation import NominalConstellation
    from mixnav.gnss.observables import simulate_observables
    from mixnav.ins.error_model import get_layout
    from mixnav.measurements.tight import TightGnss
    rng = np.random.default_rng(18)
    d = np.deg2rad
    # a drive at a random attitude, its raw observables, an epoch with its (z, H17, R)
    rpy = (d(rng.uniform(-30, 30)), d(rng.uniform(-30, 30)), d(rng.uniform(-180, 180)))
    truth, _ = generate([MotionSegment("turn", 2.0, acceleration=0.5, yaw_rate=d(10.0))],
                        InitialState((d(30.7), d(104.05), 500.0), 10.0, rpy), 100.0)
    lever = np.array([0.5, 0.2, -1.0])   # makes the attitude columns of H non-zero
    obs = simulate_observables(truth, NominalConstellation.gps(5), 1.0, lever, d(10.0), 0.3, 0.3,
                               0.003, (0.0, 0.0), (7.0, 0.5), rng)
    lay = get_layout(17)
    meas = TightGnss(obs, lever, lay)
    k, kt = 0, int(np.searchsorted(truth.time, obs.time[0] - 1e-9))
    phi0, dv0, dr0 = rng.normal(0, 2e-3, 3), rng.normal(0, 0.1, 3), rng.normal(0, 3.0, 3)
    q_est = quat_multiply(rotvec_to_quat(-phi0), truth.q_nb[kt])
    nav = np.concatenate([q_est, truth.v_n[kt] - dv0, displace(truth.lla[kt], -dr0)])
    w_b, clock = np.array([0.01, -0.02, d(10.0)]), obs.clock[k] - np.array([2.0, 0.3])
    z, H17, r = meas.measure(k, nav, w_b, clock)
    R = np.diag(r)

    # T: full column rank, T+ T = I (T^T T = I/4 for a unit quaternion), tangent to |q| = 1
    T = _quat_error_map(q_est)
    big = np.zeros((18, 17))           # x18 = [dq(4), the other 14 states] = big @ x17
    big[0:4, 0:3] = T
    big[4:, 3:] = np.eye(14)
    big_pinv = np.linalg.pinv(big)
    np.testing.assert_allclose(big_pinv @ big, np.eye(17), atol=1e-12)
    np.testing.assert_allclose(np.linalg.pinv(T), 4 * T.T, atol=1e-12)
    np.testing.assert_allclose(q_est @ T, 0.0, atol=1e-15)

    # H18: the Jacobian a quaternion filter computes, by finite differences of the predicted
    # observables in the additive quaternion (not normalised: the |q| direction has a
    # component, since C(c q) = c^2 C(q)); the chain rule gives H18 T = H17
    H18 = np.zeros((len(z), 18))
    H18[:, 4:] = H17[:, 3:]
    for j in range(4):   # central differences; step 1e-4: rounding of a 2e7 m range / 2e-4 ~ 1e-5
        n2, n3 = nav.copy(), nav.copy()
        n2[j] += 1e-4
        n3[j] -= 1e-4
        H18[:, j] = (np.concatenate(meas.predict(k, n2, w_b, clock)[:2]) -
                     np.concatenate(meas.predict(k, n3, w_b, clock)[:2])) / 2e-4
    assert np.abs(H18[:, :4] @ q_est).max() > 1.0         # a real norm-direction component
    # (to the 2e-3 of tests/test_tight.py: H17 leaves out the change of the line of sight
    # with the lever-arm displacement in the range-rate rows, about 1e-4 per metre)
    np.testing.assert_allclose(H18 @ big, H17, rtol=0, atol=2e-3 * np.abs(H17[:, 0:3]).max())

    # one update in each parameterisation from P18 = T P17 T^T
    sig = np.array([2e-3] * 3 + [0.1] * 3 + [3.0] * 3 + [1e-5] * 3 + [1e-3] * 3 + [10.0, 1.0])
    a = rng.standard_normal((17, 17))
    P17 = sig[:, None] * (a @ a.T / 17 + np.eye(17)) * sig[None, :]
    P18 = big @ P17 @ big.T
    ev = np.linalg.eigvalsh(P18)
    assert ev[0] < 1e-12 * ev[-1] and ev[1] > 1e-6 * ev[0] + 1e-14    # rank 17
    np.testing.assert_allclose(P18[:, 0:4] @ q_est, 0.0, atol=1e-15 * ev[-1])  # |q| unobservable

    def update(P, H):
        S = H @ P @ H.T + R
        K = np.linalg.solve(S, H @ P).T
        return K @ z, P - K @ H @ P
    # any H18 with H18 T = H17 gives dx18 = T dx17 and P18+ = T P17+ T^T: the finite-
    # difference H18 against H17 := H18 T, and the model's H17 against H18 := H17 T+ plus an
    # arbitrary norm-direction part
    pairs = ((H18, H18 @ big),
             (H17 @ big_pinv + np.outer(rng.standard_normal(len(z)), np.r_[q_est, np.zeros(14)]), H17))
    for h18, h17 in pairs:
        dx17, P17p = update(P17, h17)
        dx18, P18p = update(P18, h18)
        np.testing.assert_allclose(dx18, big @ dx17, rtol=0, atol=1e-9 * np.abs(big @ dx17).max())
        np.testing.assert_allclose(P18p, big @ P17p @ big.T, rtol=0, atol=1e-9 * np.abs(P18).max())
    # the corrected attitude agrees to first order: normalised q_est + dq against
    # q(dphi) * q_est differ by O(|dphi|^2), where a first-order slip would be |dphi| / 2
    dphi = dx17[0:3]
    q18 = q_est + dx18[0:4]
    q18 /= np.linalg.norm(q18)
    q17 = quat_multiply(rotvec_to_quat(dphi), q_est)
    gap = np.linalg.norm(quat_to_rotvec(quat_multiply(q18, q17 * np.array([1, -1, -1, -1]))))
    assert np.linalg.norm(dphi) > 1e-4 and gap < 0.5 * np.linalg.norm(dphi) ** 2
    # both corrections move the estimate towards the truth attitude by the same rotation
    np.testing.assert_allclose(quat_to_rotvec(quat_multiply(q18, q_est * np.array([1, -1, -1, -1]))),
                               dphi, rtol=0, atol=np.linalg.norm(dphi) ** 2)
