"""Trajectories from motion segments, and the ideal IMU that flies them.

A trajectory is a list of :class:`MotionSegment`; within a segment the
along-track acceleration and the Euler-angle rates are constant, so speed,
attitude and NED velocity are closed-form functions of time. Position follows
from integrating the velocity (Picard iteration of the lat/lon/h equations on
a half-step grid, Simpson's rule), and the ideal IMU increments are Simpson
integrals of the true angular rate and specific force over each IMU interval:

    w_ib^b = w_nb^b(Euler rates) + C_bn (w_ie^n + w_en^n)
    f^b    = C_bn (dv_n/dt + (2 w_ie^n + w_en^n) x v_n - g^n)

They are computed from the motion itself, not by inverting the
mechanization, so the round-trip test of ``tests/test_mechanization.py``
checks the strapdown algorithm against an independent truth.

The velocity is along the body x axis rotated by pitch and yaw (no sideslip,
no angle of attack): the motion of a car or of a coordinated aircraft. With
:class:`NhcViolations` a land vehicle also slips sideways and bounces: in the
vehicle (body) frame its velocity is

    v^v = speed * [sqrt(1 - sin^2 beta - sin^2 alpha), sin beta, sin alpha]

with smooth random angles ``beta(t)`` (sideslip) and ``alpha(t)`` (bumps, down
positive), so ``v_n = C_nv v^v`` and ``dv_n/dt = C_nv (w_nv^v x v^v + dv^v/dt)``
exactly; the attitude still follows the segments (a stopped car neither turns
nor slides). :func:`mount` then turns the vehicle's truth and ideal IMU into
those of an IMU mounted at a fixed rotation ``C_vb`` in the vehicle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import cumulative_simpson
from scipy.interpolate import CubicSpline

from ..attitude import dcm_to_quat, euler_to_dcm, euler_to_quat, quat_multiply
from ..data import ImuData, Trajectory
from ..errors import ConfigError
from ..geodesy import earth

#: Largest pitch the generator allows [rad]; Euler angles are singular at 90 deg.
MAX_PITCH = np.deg2rad(80.0)


@dataclass(frozen=True)
class MotionSegment:
    """One piece of motion with constant acceleration and Euler-angle rates.

    Attributes
    ----------
    kind : str
        ``static``, ``uniform``, ``accelerate``, ``turn`` or ``climb`` (for
        messages; the motion is set by the numbers).
    duration : float
        [s]; must be a whole number of IMU intervals.
    acceleration : float
        Along-track acceleration [m/s^2].
    roll_rate, pitch_rate, yaw_rate : float
        Euler angle rates [rad/s].
    """

    kind: str
    duration: float
    acceleration: float = 0.0
    roll_rate: float = 0.0
    pitch_rate: float = 0.0
    yaw_rate: float = 0.0


@dataclass(frozen=True)
class InitialState:
    """Where and how the trajectory starts.

    ``lla`` in rad/rad/m, ``speed`` [m/s] along the body x axis, ``rpy`` [rad].
    """

    lla: tuple[float, float, float]
    speed: float
    rpy: tuple[float, float, float]


@dataclass(frozen=True)
class NhcViolations:
    """Sideslip ``slip(t)`` and bump ``bump(t)`` angles [rad] of a land vehicle.

    Each is None (no violation) or a callable ``f(t, nu)`` giving the angle
    (``nu = 0``) or its ``nu``-th time derivative at times ``t`` [s] since the
    start of the trajectory, e.g. a :class:`scipy.interpolate.CubicSpline`
    from :func:`smooth_gauss_markov`. They must be twice continuously
    differentiable between IMU samples (the ideal IMU integrates their
    derivative with Simpson's rule).
    """

    slip: object = None
    bump: object = None


def smooth_gauss_markov(duration: float, sigma: float, tau: float, dt: float,
                        rng: np.random.Generator) -> CubicSpline:
    """A smooth random angle with std ``sigma`` and correlation time ``tau``.

    A first-order Gauss-Markov sequence (stationary start) at knots every
    ``tau / 4`` rounded to a whole number ``m >= 1`` of IMU intervals ``dt``
    (so every IMU interval lies inside one spline piece), joined by a natural
    C2 cubic spline over ``[0, duration]``. Its std at the knots is ``sigma``,
    between them slightly less (0.99 sigma averaged over time, measured over
    20 x 4000 s for tau = 0.5-5 s: the spline smooths the sequence's steps);
    its autocorrelation at lags beyond a knot spacing is close to
    ``exp(-lag / tau)``. Its rate is about ``sigma sqrt(8) / tau``: a short
    ``tau`` makes a jerky vehicle.
    """
    m = max(1, int(round(tau / 4.0 / dt)))
    h = m * dt
    n = max(2, int(np.ceil(duration / h - 1e-9)) + 1)
    phi = np.exp(-h / tau)
    w = rng.standard_normal(n)
    x = np.empty(n)
    x[0] = sigma * w[0]
    q = sigma * np.sqrt(1.0 - phi * phi)
    for k in range(1, n):
        x[k] = phi * x[k - 1] + q * w[k]
    return CubicSpline(h * np.arange(n), x, bc_type="natural")


def draw_violations(duration: float, imu_rate: float, slip_sigma: float, slip_time: float,
                    bump_sigma: float, bump_time: float, rng: np.random.Generator) -> NhcViolations:
    """Slip, then bump angles from ``rng`` (a zero sigma: that violation off, nothing drawn)."""
    dt = 1.0 / imu_rate
    slip = smooth_gauss_markov(duration, slip_sigma, slip_time, dt, rng) if slip_sigma > 0 else None
    bump = smooth_gauss_markov(duration, bump_sigma, bump_time, dt, rng) if bump_sigma > 0 else None
    return NhcViolations(slip, bump)


def _violate(kin, times, viol: NhcViolations, acc):
    """Add the slip/bump velocity (and its derivative) to one node's kinematics."""
    speed, rpy, v_n, a_n, w = kin
    z = np.zeros_like(times)
    sb = db = sa = da = z
    if viol.slip is not None:
        b, b1 = viol.slip(times, 0), viol.slip(times, 1)
        sb, db = np.sin(b), np.cos(b) * b1
    if viol.bump is not None:
        a, a1 = viol.bump(times, 0), viol.bump(times, 1)
        sa, da = np.sin(a), np.cos(a) * a1
    r = np.sqrt(1.0 - sb * sb - sa * sa)
    delta = np.stack([r - 1.0, sb, sa], -1)
    ddelta = np.stack([-(sb * db + sa * da) / r, db, da], -1)
    c_nv = euler_to_dcm(rpy)
    dv_v = speed[:, None] * delta
    da_v = (acc * np.ones_like(speed))[:, None] * delta + speed[:, None] * (np.cross(w, delta) + ddelta)
    v_n = v_n + np.einsum("kij,kj->ki", c_nv, dv_v)
    a_n = a_n + np.einsum("kij,kj->ki", c_nv, da_v)
    return (speed, rpy, v_n, a_n, w), np.arcsin(sb), np.arcsin(sa)


def _kinematics(s0, acc, ang0, rates, tau):
    """Speed, Euler angles, NED velocity and acceleration, body rates at tau.

    All inputs broadcast over a leading axis (one row per evaluation point).
    """
    speed = s0 + acc * tau
    rpy = ang0 + rates * tau[:, None]
    roll, pitch, yaw = rpy[:, 0], rpy[:, 1], rpy[:, 2]
    sr, cr, sp, cp, sy, cy = np.sin(roll), np.cos(roll), np.sin(pitch), np.cos(pitch), np.sin(yaw), np.cos(yaw)
    u = np.stack([cp * cy, cp * sy, -sp], -1)
    du_dp = np.stack([-sp * cy, -sp * sy, -cp], -1)
    du_dy = np.stack([-cp * sy, cp * cy, np.zeros_like(cp)], -1)
    v_n = speed[:, None] * u
    a_n = (acc * np.ones_like(speed))[:, None] * u + speed[:, None] * (
        rates[:, 1:2] * du_dp + rates[:, 2:3] * du_dy
    )
    rr, pr, yr = rates[:, 0], rates[:, 1], rates[:, 2]
    w_nb_b = np.stack([rr - yr * sp, pr * cr + yr * sr * cp, -pr * sr + yr * cr * cp], -1)
    return speed, rpy, v_n, a_n, w_nb_b


def _segment_table(segments, initial: InitialState, imu_rate: float, source: str | None):
    """Start state of each segment and its sample count; validates the list."""
    if not segments:
        raise ConfigError("the segment list is empty: no trajectory", file=source, key="trajectory.segments")
    s = float(initial.speed)
    ang = np.array(initial.rpy, dtype=float)
    rows = []
    for i, seg in enumerate(segments):
        key = f"trajectory.segments[{i}]"
        n = seg.duration * imu_rate
        if seg.duration <= 0 or abs(n - round(n)) > 1e-6:
            raise ConfigError(
                f"{seg.kind} segment duration {seg.duration} s must be positive and a whole "
                f"number of IMU intervals (1/{imu_rate:g} s)", file=source, key=f"{key}.duration")
        if seg.kind == "static" and (s != 0.0 or seg.acceleration != 0.0):
            raise ConfigError(f"static segment starts at speed {s:g} m/s; the vehicle must be at rest",
                              file=source, key=key)
        rates = np.array([seg.roll_rate, seg.pitch_rate, seg.yaw_rate])
        rows.append((s, seg.acceleration, ang.copy(), rates, int(round(n))))
        s_end = s + seg.acceleration * seg.duration
        if s_end < -1e-9:
            raise ConfigError(f"speed becomes negative ({s_end:g} m/s) at the end of this segment",
                              file=source, key=key)
        s = max(s_end, 0.0) if abs(s_end) < 1e-9 else s_end
        ang = ang + rates * seg.duration
        if abs(ang[1]) > MAX_PITCH or abs(ang[0]) > MAX_PITCH:
            raise ConfigError("pitch or roll exceeds 80 deg at the end of this segment", file=source, key=key)
    return rows


def generate(segments, initial: InitialState, imu_rate: float, t0: float = 0.0,
             source: str | None = None,
             violations: NhcViolations | None = None) -> tuple[Trajectory, ImuData]:
    """Fly the segments; return the truth at the IMU rate and ideal increments.

    Parameters
    ----------
    segments : sequence of MotionSegment
    initial : InitialState
    imu_rate : float
        IMU sampling rate [Hz].
    t0 : float
        Start time [s].
    source : str, optional
        Scenario file, named in error messages.
    violations : NhcViolations, optional
        Sideslip and bump angles of a land vehicle (functions of ``t - t0``);
        None: the velocity stays along the body x axis.

    Returns
    -------
    truth : Trajectory
        States at ``t0 + k/imu_rate``, k = 0..N (N + 1 rows). ``extra``:
        ``w_ib_b`` and ``w_nb_b`` (body rates at the samples [rad/s]),
        ``q_nv`` (the vehicle's attitude; here the body's), and with
        ``violations`` the angles ``slip`` and ``bump`` [rad] at the samples.
    imu : ImuData
        N error-free increments; increment k covers ``(t_{k-1}, t_k]``.
    """
    table = _segment_table(segments, initial, imu_rate, source)
    dt = 1.0 / imu_rate
    n = sum(r[4] for r in table)
    # Per-interval segment parameters and the time offset of its start.
    s0 = np.concatenate([np.full(r[4], r[0]) for r in table])
    acc = np.concatenate([np.full(r[4], r[1]) for r in table])
    ang0 = np.concatenate([np.tile(r[2], (r[4], 1)) for r in table])
    rates = np.concatenate([np.tile(r[3], (r[4], 1)) for r in table])
    k_in_seg = np.concatenate([np.arange(r[4]) for r in table]).astype(float)

    # Three Simpson nodes per interval: start, middle, end (offsets in the segment).
    taus = [k_in_seg * dt, (k_in_seg + 0.5) * dt, (k_in_seg + 1.0) * dt]
    kin = [_kinematics(s0, acc, ang0, rates, tau) for tau in taus]
    angles = None
    if violations is not None and (violations.slip is not None or violations.bump is not None):
        k_all = np.arange(n, dtype=float)
        out = [_violate(kin[j], (k_all + f) * dt, violations, acc) for j, f in enumerate((0.0, 0.5, 1.0))]
        kin = [o[0] for o in out]
        angles = {"slip": np.concatenate([out[0][1][:1], out[2][1]]),
                  "bump": np.concatenate([out[0][2][:1], out[2][2]])}

    # Half-step grid: node 2k is t_k, node 2k+1 the middle of interval k+1.
    v_grid = np.empty((2 * n + 1, 3))
    v_grid[0] = kin[0][2][0]
    v_grid[1::2] = kin[1][2]
    v_grid[2::2] = kin[2][2]
    t_grid = t0 + 0.5 * dt * np.arange(2 * n + 1)
    lat0, lon0, h0 = initial.lla
    h = h0 - cumulative_simpson(v_grid[:, 2], x=t_grid, initial=0.0)
    lat = np.full_like(h, lat0)
    # Picard iteration; the radii change by ~1e-6 per km so three sweeps reach
    # round-off.
    for _ in range(4):
        rm, rn = earth.radii(lat)
        lat = lat0 + cumulative_simpson(v_grid[:, 0] / (rm + h), x=t_grid, initial=0.0)
    rm, rn = earth.radii(lat)
    lon = lon0 + cumulative_simpson(v_grid[:, 1] / ((rn + h) * np.cos(lat)), x=t_grid, initial=0.0)

    def body_rates_and_force(node, grid_idx):
        _, rpy, v_n, a_n, w_nb_b = kin[node]
        la, hh = lat[grid_idx], h[grid_idx]
        c_nb = euler_to_dcm(rpy)
        w_ie = earth.earth_rate_ned(la)
        w_en = earth.transport_rate_ned(la, hh, v_n)
        g_n = earth.gravity_ned(la, hh)
        w_ib_b = w_nb_b + np.einsum("kji,kj->ki", c_nb, w_ie + w_en)
        f_n = a_n + np.cross(2.0 * w_ie + w_en, v_n) - g_n
        f_b = np.einsum("kji,kj->ki", c_nb, f_n)
        return w_ib_b, f_b

    idx = np.arange(n)
    w0, f0 = body_rates_and_force(0, 2 * idx)
    w1, f1 = body_rates_and_force(1, 2 * idx + 1)
    w2, f2 = body_rates_and_force(2, 2 * idx + 2)
    dtheta = dt / 6.0 * (w0 + 4.0 * w1 + w2)
    dvel = dt / 6.0 * (f0 + 4.0 * f1 + f2)

    rpy_t = np.vstack([kin[0][1][:1], kin[2][1]])
    v_t = np.vstack([kin[0][2][:1], kin[2][2]])
    lla_t = np.stack([lat[::2], lon[::2], h[::2]], -1)
    t_imu = t0 + dt * np.arange(n + 1)
    q_t = euler_to_quat(rpy_t)
    extra = {"w_ib_b": np.vstack([w0[:1], w2]), "w_nb_b": np.vstack([kin[0][4][:1], kin[2][4]]),
             "q_nv": q_t}
    if angles is not None:
        extra.update(angles)
    truth = Trajectory(time=t_imu, lla=lla_t, v_n=v_t, q_nb=q_t, extra=extra)
    imu = ImuData(time=t_imu[1:], dt=np.full(n, dt), dtheta=dtheta, dvel=dvel, source=source)
    return truth, imu


def mount(truth: Trajectory, imu: ImuData, c_vb: np.ndarray) -> tuple[Trajectory, ImuData]:
    """The truth and ideal IMU of an IMU mounted at ``C_vb`` in the vehicle.

    ``truth``/``imu`` are the vehicle's (body = vehicle frame v, as
    :func:`generate` gives them); ``C_vb`` maps IMU-frame (b) vectors into
    the vehicle frame. Returns the truth with the IMU's attitude
    ``C_nb = C_nv C_vb`` (``extra["q_nv"]`` keeps the vehicle's, ``w_ib_b``
    and ``w_nb_b`` are rotated into b) and the increments in b,
    ``dtheta_b = C_bv dtheta_v`` (exact: the rotation is constant).
    Position and velocity are unchanged (the IMU is the reference point).
    """
    c_vb = np.asarray(c_vb, dtype=float)
    q_vb = dcm_to_quat(c_vb)
    extra = dict(truth.extra)
    extra["q_nv"] = truth.q_nb
    for k in ("w_ib_b", "w_nb_b"):
        if k in extra:
            extra[k] = extra[k] @ c_vb  # rows: (C_bv w)^T = w^T C_vb
    out = Trajectory(time=truth.time, lla=truth.lla, v_n=truth.v_n,
                     q_nb=quat_multiply(truth.q_nb, q_vb), extra=extra)
    return out, ImuData(time=imu.time, dt=imu.dt, dtheta=imu.dtheta @ c_vb, dvel=imu.dvel @ c_vb,
                        source=imu.source, gaps=imu.gaps)
