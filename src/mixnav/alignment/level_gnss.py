"""Alignment for the common start of a land vehicle: at rest, then slow motion.

A MEMS gyro cannot gyrocompass (Earth rate 15 deg/h against biases of
10-1000 deg/h), and the in-motion alignment from GNSS velocity alone
(:mod:`.motion`) guesses roll zero and takes the pitch of the path, not of the
IMU. This one measures what each phase can measure:

1. **Rest** (the first ``rest_duration`` seconds): roll and pitch from the
   mean specific force (levelling, :func:`.coarse.coarse_align` without the
   gyro heading), the gyro bias from the mean angular rate.
2. **Carry** (from the end of the rest window to the first GNSS fix moving at
   ``min_speed`` or more): the attitude is propagated with the
   bias-compensated angle increments, attitude only, so roll and pitch stay
   right when the car tilts after leaving its parking spot; the heading is
   arbitrary meanwhile. The Earth rate the gyros sensed at rest is in the bias
   estimate and is removed with it; what that leaves is the change of the body
   components of the Earth rate as the car turns, at most ``2 Omega_ie``
   (30 deg/h, 0.008 deg/s), and the transport rate (1e-6 rad/s at 5 m/s):
   both are neglected, below a MEMS gyro's bias instability over the few
   seconds of a carry.
3. **Fix**: the vehicle moves along its forward axis (``forward_b``, the
   vehicle x axis in the body frame, ``C_vb^T e_x`` with a vehicle mounting),
   so the heading is the yaw that turns the carried forward axis onto the GNSS
   track angle (closed form below). Velocity from the fix, position of the
   IMU from the antenna lever arm.

The rest window must be at rest (else the levelling sees acceleration as tilt
and the bias estimate holds the turn rate). Its 1 s blocks are held to the
thresholds of :func:`mixnav.measurements.stillness.detect_still` (standard
deviation of the specific-force magnitude below ``accel_std``, mean
angular-rate magnitude below ``gyro_rate``): at most ``MAX_DISTURBED`` (20 %)
of them may fail (brief jolts of a parked car: a door, a passenger). The mean
specific force of the last second must point within ``MAX_END_TILT`` (1 deg)
of the window's mean (the window must end before the car pulls away), the
mean specific force must be gravity within 5 %, and no GNSS fix inside the
window may move at ``min_speed``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..attitude import dcm_to_euler, dcm_to_quat, euler_to_dcm, wrap_angle
from ..data import GnssFixes, ImuData
from ..errors import ArgumentError
from ..geodesy import earth
from ..geodesy.frames import displace
from .coarse import coarse_align
from .in_motion import fix_velocities

#: Largest fraction of the rest window's 1 s blocks allowed to fail the rest
#: thresholds: a door closing or someone getting in is brief and averages out
#: (drive-0708: 3 of 30 blocks, 0.12-0.21 m/s^2, at 19-27 s, parked).
MAX_DISTURBED = 0.2

#: Largest angle [rad] between the mean specific force of the rest window's last
#: second and that of the whole window. A vehicle pulling away tilts it by about
#: its acceleration / g (0.2 m/s^2: 1.2 deg), which the block scatter may not see;
#: drive-0708's parked jolts move 1 s means by at most 0.4 deg.
MAX_END_TILT = np.deg2rad(1.0)


@dataclass(frozen=True)
class LevelGnssAlignment:
    """Result of :func:`align_level_then_gnss`.

    Attributes
    ----------
    time : float
        Time of the fix used [s]: the alignment epoch.
    q_nb : ndarray (4,)
        Attitude at ``time``, body to NED, scalar first.
    rpy : ndarray (3,)
        The same as roll, pitch, yaw [rad].
    v_n : ndarray (3,)
        Velocity of the fix [m/s].
    lla : ndarray (3,)
        Position of the IMU [rad, rad, m].
    index : int
        The fix used.
    gyro_bias : ndarray (3,)
        Mean angular rate over the rest window [rad/s] (the gyro bias plus the
        Earth rate in the body frame, at most 7.3e-5 rad/s).
    rest_end : float
        End of the rest window [s] (time of its last IMU sample).
    rest_rpy : ndarray (2,)
        Roll and pitch levelled at the end of the rest window [rad].
    level_sigma_noise : float
        1-sigma roll/pitch error from the scatter of the specific force over
        the rest window [rad] (from 1 s block means); an accelerometer bias
        ``b`` adds ``b / g`` on top, which levelling cannot separate.
    disturbed_blocks, rest_blocks : int
        1 s blocks of the rest window that failed the rest thresholds, and all of them.
    """

    time: float
    q_nb: np.ndarray
    rpy: np.ndarray
    v_n: np.ndarray
    lla: np.ndarray
    index: int
    gyro_bias: np.ndarray
    rest_end: float
    rest_rpy: np.ndarray
    level_sigma_noise: float
    disturbed_blocks: int
    rest_blocks: int


def _block_stats(imu: ImuData, block: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per consecutive ``block`` [s] block (the last partial block joins the one
    before): the standard deviation of the specific-force magnitude [m/s^2] (K,),
    the mean angular-rate magnitude [rad/s] (K,) and the mean specific force
    [m/s^2] (K, 3)."""
    nb = max(int(round(block / float(np.median(imu.dt)))), 2)
    f = np.linalg.norm(imu.dvel, axis=1) / imu.dt
    w = np.linalg.norm(imu.dtheta, axis=1) / imu.dt
    edges = np.arange(nb, len(f), nb)
    if len(edges) and len(f) - edges[-1] < nb:
        edges = edges[:-1]
    parts = np.split(np.arange(len(f)), edges)
    return (np.array([np.std(f[k]) for k in parts]), np.array([np.mean(w[k]) for k in parts]),
            np.array([imu.dvel[k].sum(0) / imu.dt[k].sum() for k in parts]))


def _product(rotvecs: np.ndarray) -> np.ndarray:
    """``exp([r_1 x]) exp([r_2 x]) ... exp([r_n x])`` for rotation vectors (n, 3) [rad],
    by pairwise products (log2 n vectorised steps)."""
    if len(rotvecs) == 0:
        return np.eye(3)
    r = Rotation.from_rotvec(rotvecs)
    while len(r) > 1:
        if len(r) % 2:
            r = Rotation.concatenate([r, Rotation.identity(1)])
        r = r[0::2] * r[1::2]   # keeps the order: (R1 R2)(R3 R4)...
    return r[0].as_matrix()


def align_level_then_gnss(imu: ImuData, fixes: GnssFixes, lever_b: np.ndarray, rest_duration: float,
                          min_speed: float, forward_b: np.ndarray | None = None,
                          accel_std: float = 0.1, gyro_rate: float = 0.03) -> LevelGnssAlignment:
    """Level at rest, carry the attitude with the gyros, take the heading from GNSS once moving.

    Parameters
    ----------
    imu : ImuData
        Increments in the body frame, starting with the vehicle at rest.
    fixes : GnssFixes
        Antenna fixes on the IMU's time axis; velocities are used when given,
        else central differences of the positions.
    lever_b : ndarray (3,)
        Antenna relative to the IMU in the body frame [m].
    rest_duration : float
        Length of the rest window from the IMU's start time [s].
    min_speed : float
        Horizontal speed [m/s] at which the GNSS track gives the heading.
    forward_b : ndarray (3,), optional
        The direction of travel in the body frame (the vehicle x axis,
        ``C_vb^T e_x``); the body x axis when None.
    accel_std, gyro_rate : float
        Rest thresholds per 1 s block [m/s^2], [rad/s] (the defaults of
        :func:`~mixnav.measurements.stillness.detect_still`, measured on
        drive-0708: parked 0.02-0.08 and 0.005-0.025, moving 0.13-1.7 and 0.03-0.5).

    Raises
    ------
    ArgumentError
        ``rest_duration``: the window holds fewer than 10 samples or is not at
        rest; ``min_speed``: no fix after the window reaches it;
        ``forward_b``: not a direction, or (nearly) vertical after levelling.
    """
    for name, v in (("rest_duration", rest_duration), ("min_speed", min_speed)):
        if not (np.isfinite(v) and v > 0):
            raise ArgumentError(f"must be positive, got {v!r}", argument=name)
    fwd = np.array([1.0, 0.0, 0.0]) if forward_b is None else np.asarray(forward_b, dtype=float)
    if fwd.shape != (3,) or not np.all(np.isfinite(fwd)) or np.linalg.norm(fwd) < 1e-9:
        raise ArgumentError(f"must be a non-zero 3-vector, got {forward_b!r}", argument="forward_b")
    fwd = fwd / np.linalg.norm(fwd)
    src = imu.source or "the IMU"

    # 1. rest: levelling and gyro bias
    rest = imu.time <= imu.start_time + rest_duration
    n_rest = int(rest.sum())
    if n_rest < 10:
        raise ArgumentError(f"the rest window of {rest_duration:g} s holds {n_rest} IMU samples of {src}; "
                            f"at least 10 are needed", argument="rest_duration")
    still = ImuData(imu.time[rest], imu.dt[rest], imu.dtheta[rest], imu.dvel[rest], imu.source)
    t_end = float(still.time[-1])
    lat, h = float(fixes.lla[0, 0]), float(fixes.lla[0, 2])
    g = float(earth.normal_gravity(lat, h))
    f_std, w_rate, f_blocks = _block_stats(still, 1.0)
    moved = (f_std >= accel_std) | (w_rate >= gyro_rate)
    f_all = still.dvel.sum(0) / still.dt.sum()
    f_last = f_blocks[-1]
    turn = np.arccos(np.clip(f_last @ f_all / (np.linalg.norm(f_last) * np.linalg.norm(f_all)), -1.0, 1.0))
    why = []
    if abs(np.linalg.norm(f_all) / g - 1.0) > 0.05:   # coarse_align's test: moving, or wrong units
        why.append(f"mean specific force {np.linalg.norm(f_all):.3f} m/s^2 is not gravity {g:.3f} within 5 %")
    if moved.mean() > MAX_DISTURBED:
        why.append(f"{moved.sum()} of {moved.size} 1 s blocks move (specific-force magnitude scatter up to "
                   f"{f_std.max():.3f} m/s^2, at rest below {accel_std:g}; mean rate up to "
                   f"{w_rate.max():.4f} rad/s, at rest below {gyro_rate:g})")
    if turn > MAX_END_TILT:
        why.append(f"the specific force of its last second points {np.degrees(turn):.2f} deg away from the "
                   f"window's mean (at rest below {np.degrees(MAX_END_TILT):g} deg): the vehicle is accelerating")
    v = fix_velocities(fixes)
    speed = np.hypot(v[:, 0], v[:, 1])
    inside = np.nonzero((fixes.time <= t_end) & (speed >= min_speed))[0]
    if inside.size:
        k = int(inside[0])
        why.append(f"the GNSS fix at {fixes.time[k]:.2f} s moves at {speed[k]:.2f} m/s")
    if why:
        raise ArgumentError(f"the IMU ({src}) is not at rest over the first {rest_duration:g} s: "
                            + "; ".join(why) + "; shorten the rest window", argument="rest_duration")
    lev = coarse_align(still, lat, h, use_gyro_heading=False, yaw=0.0, block=1.0)
    bias = still.dtheta.sum(0) / still.dt.sum()

    # 3. the first fix moving fast enough after the rest window
    ok = np.nonzero((speed >= min_speed) & (fixes.time > t_end))[0]
    if ok.size == 0:
        after = speed[fixes.time > t_end]
        fastest = f"{after.max():.2f} m/s" if after.size else "no fixes"
        raise ArgumentError(f"no GNSS fix of {fixes.source or 'the GNSS file'} after the rest window "
                            f"({t_end:.2f} s) reaches {min_speed:g} m/s (fastest {fastest}): "
                            f"cannot take the heading", argument="min_speed")
    i = int(ok[0])
    t_fix = float(fixes.time[i])

    # 2. carry from t_end to t_fix: increments ending after t_end, the one
    # straddling t_fix taken in part
    k0 = int(np.searchsorted(imu.time, t_end, side="right"))
    k1 = min(int(np.searchsorted(imu.time, t_fix, side="left")) + 1, len(imu))
    dt = imu.dt[k0:k1]
    frac = np.clip((t_fix - (imu.time[k0:k1] - dt)) / dt, 0.0, 1.0)
    rv = (imu.dtheta[k0:k1] - bias * dt[:, None]) * frac[:, None]
    c_carried = euler_to_dcm(lev.rpy) @ _product(rv)
    roll, pitch, _ = dcm_to_euler(c_carried)

    # heading: C_nb(r, p, psi) = Rz(psi) C_nb(r, p, 0), so the forward axis'
    # horizontal direction alpha at yaw 0 turns by psi onto the track
    u = euler_to_dcm(np.array([roll, pitch, 0.0])) @ fwd
    if np.hypot(u[0], u[1]) < 0.1:
        raise ArgumentError(f"the forward axis {fwd} is within 6 deg of vertical after levelling "
                            f"(roll {np.degrees(roll):.1f} deg, pitch {np.degrees(pitch):.1f} deg)",
                            argument="forward_b")
    track = np.arctan2(v[i, 1], v[i, 0])
    psi = float(wrap_angle(track - np.arctan2(u[1], u[0])))
    rpy = np.array([roll, pitch, psi])
    c_nb = euler_to_dcm(rpy)
    lla = displace(fixes.lla[i], -(c_nb @ np.asarray(lever_b, dtype=float)))
    return LevelGnssAlignment(time=t_fix, q_nb=dcm_to_quat(c_nb), rpy=rpy, v_n=v[i].copy(), lla=lla, index=i,
                              gyro_bias=bias, rest_end=t_end, rest_rpy=lev.rpy[:2].copy(),
                              level_sigma_noise=lev.level_sigma_noise,
                              disturbed_blocks=int(moved.sum()), rest_blocks=int(moved.size))
