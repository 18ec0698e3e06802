"""Turn a validated scenario into simulated data for one seeded run."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..attitude import euler_to_dcm, quat_multiply, rotvec_to_quat
from ..config.loader import gnss_noise, imu_model, imu_white_noise
from ..config.scenario_schema import (AccelerateSegment, ClimbSegment, Scenario, StaticSegment,
                                      TurnSegment, UniformSegment)
from ..data import GnssFixes, ImuData, OdometerData, Trajectory
from ..data import InitialState
from ..ins.imu_model import ImuErrorDraw, ImuErrorModel, corrupt
from .gnss import GnssFixModel, simulate_fixes
from .odometer import simulate_odometer
from .rng import Streams
from .trajectory import InitialState as TrajectoryStart
from .trajectory import MotionSegment, draw_violations, generate, mount
from ..geodesy.frames import displace


@dataclass(frozen=True)
class VehicleTruth:
    """The true installation and odometer errors of a simulated land vehicle.

    Attributes
    ----------
    imu_misalignment : ndarray (3,)
        Roll, pitch, yaw of the IMU axes b in the vehicle axes v [rad]
        (``[installation] imu_misalignment``; zeros without it).
    C_vb : ndarray (3, 3)
        ``euler_to_dcm(imu_misalignment)``: IMU-frame vectors into the
        vehicle frame (x forward, y right, z down).
    odometer_scale : float or None
        The true odometer scale-factor error k (speed = (1 + k) v^v_x + noise);
        None without ``[odometer]``.
    odometer_lever_arm : ndarray (3,) or None
        The wheel point from the IMU in the IMU frame b [m].

    The per-sample truth of the vehicle is in ``SimulatedRun.truth.extra``:
    ``q_nv`` (vehicle attitude), ``w_nb_b`` (body rate w.r.t. NED, b frame),
    ``w_ib_b``, and with ``[vehicle]`` the angles ``slip`` and ``bump`` [rad].
    """

    imu_misalignment: np.ndarray
    C_vb: np.ndarray
    odometer_scale: float | None = None
    odometer_lever_arm: np.ndarray | None = None


@dataclass(frozen=True)
class SimulatedRun:
    """Everything one seeded run of a scenario needs and knows.

    ``truth`` is the IMU's (its attitude ``C_nb = C_nv C_vb`` with a
    mounting); ``odometer`` the simulated wheel speeds (None without
    ``[odometer]``); ``vehicle`` the true mounting and odometer errors.
    """

    seed: int
    truth: Trajectory
    imu_ideal: ImuData
    imu: ImuData
    imu_draw: ImuErrorDraw
    imu_model: ImuErrorModel
    fixes: GnssFixes
    init: InitialState
    outages: tuple
    observations: object = None  # GnssObservations when the scenario has [gnss.satellites]
    odometer: OdometerData | None = None
    vehicle: VehicleTruth | None = None
    #: (times (M,) [s], bias (M, 3) NED [m]): the systematic part of each simulated fix's
    #: position error (multipath component means), what a bias estimate is scored against
    gnss_bias: tuple | None = None


def motion_segments(sc: Scenario) -> list[MotionSegment]:
    """The scenario's segments as :class:`MotionSegment` (SI)."""
    out = []
    for s in sc.trajectory.segments:
        if isinstance(s, (StaticSegment, UniformSegment)):
            out.append(MotionSegment(s.type, s.duration))
        elif isinstance(s, AccelerateSegment):
            out.append(MotionSegment(s.type, s.duration, acceleration=s.acceleration))
        elif isinstance(s, TurnSegment):
            out.append(MotionSegment(s.type, s.duration, yaw_rate=s.rate))
        elif isinstance(s, ClimbSegment):
            out.append(MotionSegment(s.type, s.duration, pitch_rate=s.rate))
    return out


def mounting(sc: Scenario) -> np.ndarray:
    """``C_vb`` of the scenario's ``[installation]`` (identity without it)."""
    inst = sc.installation
    return euler_to_dcm(np.zeros(3) if inst is None else np.asarray(inst.imu_misalignment, dtype=float))


def truth_and_ideal_imu(sc: Scenario, source: str | None = None):
    """The deterministic part of a scenario: truth and ideal increments.

    With ``[vehicle]`` the sideslip/bump angles are drawn from stream
    ``vehicle`` of ``vehicle.seed`` (part of the trajectory, not of a run);
    with ``[installation]`` the truth and increments are the mounted IMU's.
    """
    tr = sc.trajectory
    start = TrajectoryStart(lla=tuple(tr.start), speed=tr.speed, rpy=tuple(tr.attitude))
    viol = None
    v = sc.vehicle
    if v is not None and (v.slip_sigma > 0 or v.bump_sigma > 0):
        viol = draw_violations(sc.duration, sc.imu.rate, v.slip_sigma, v.slip_time, v.bump_sigma,
                               v.bump_time, Streams(v.seed).get("vehicle"))
    truth, imu = generate(motion_segments(sc), start, sc.imu.rate, source=source, violations=viol)
    if sc.installation is not None and any(a != 0.0 for a in sc.installation.imu_misalignment):
        truth, imu = mount(truth, imu, mounting(sc))
    return truth, imu


def vehicle_truth(sc: Scenario) -> VehicleTruth:
    """The true mounting and odometer errors of a scenario."""
    mis = np.zeros(3) if sc.installation is None else np.asarray(sc.installation.imu_misalignment, dtype=float)
    o = sc.odometer
    return VehicleTruth(imu_misalignment=mis, C_vb=mounting(sc),
                        odometer_scale=None if o is None else float(o.scale_factor),
                        odometer_lever_arm=None if o is None else np.asarray(o.lever_arm, dtype=float))


def simulate(sc: Scenario, seed: int, source: str | None = None, ideal=None) -> SimulatedRun:
    """Draw one run: IMU errors, GNSS noise and the initial estimation error.

    Streams (independent, from ``seed``): ``imu``, ``gnss``, ``init``, ``odometer`` (drawn
    only with ``[odometer]``) and ``gnss-loss`` (only with ``[gnss] losses``).
    ``ideal`` may pass a precomputed ``(truth, imu_ideal)`` for Monte Carlo.
    """
    streams = Streams(seed)
    truth, imu_ideal = ideal if ideal is not None else truth_and_ideal_imu(sc, source)
    model = imu_model(sc.imu.grade, sc.imu.errors, source, "imu.errors", "imu.grade")
    white = imu_white_noise(sc, source)
    # the process is sampled per channel (3 gyro, then 3 accelerometer) at the IMU epochs,
    # or with imu.white_noise_hold at the ends of the hold intervals
    noise = None if white is None else (lambda g, times, c: white.sample(times, c, g))
    imu, draw = corrupt(imu_ideal, model, streams.get("imu"), white_noise=noise,
                        hold=sc.imu.white_noise_hold)
    g = sc.gnss
    fix_model = GnssFixModel(
        rate=g.rate, pos_sigma=np.asarray(g.position_sigma),
        vel_sigma=None if g.velocity_sigma is None else np.asarray(g.velocity_sigma),
        lever_arm=np.asarray(g.lever_arm), outages=tuple(tuple(o) for o in g.outages))
    pos_noise, vel_noise = gnss_noise(sc, source)
    fixes, bias = simulate_fixes(truth, fix_model, streams.get("gnss"), position_noise=pos_noise,
                                 velocity_noise=vel_noise, with_bias=True)
    gnss_bias = (fixes.time.copy(), bias)   # before losses: looked up by time
    if g.losses:
        fixes = _lose_fixes(fixes, g.losses, streams.get("gnss-loss"))
    init = initial_estimate(truth, sc, streams.get("init"))
    obs, outages = None, fix_model.outages
    if g.satellites is not None:
        obs = simulate_satellites(sc, truth, streams, source)
        fixes = _without_fixes_below_four(fixes, obs)
        # satellite outages leaving fewer than 4 are windows with no fix: scored like outages
        lost = {tuple(o.window) for o in g.satellites.outages
                if o.keep is not None and o.keep < 4 and o.fraction is None}
        outages = tuple(sorted(set(outages) | lost))
    vehicle = vehicle_truth(sc)
    odo = None
    if sc.odometer is not None:
        o = sc.odometer
        odo = simulate_odometer(truth, o.rate, o.sigma, o.scale_factor, vehicle.odometer_lever_arm,
                                vehicle.C_vb, streams.get("odometer"), quantum=o.quantum, source=source)
    return SimulatedRun(seed, truth, imu_ideal, imu, draw, model, fixes, init, outages, obs,
                        odometer=odo, vehicle=vehicle, gnss_bias=gnss_bias)


def _lose_fixes(fixes: GnssFixes, losses, rng) -> GnssFixes:
    """The fixes without those lost: inside each ``(start, end, p)`` window (``start <= t <
    end``), each fix independently with probability ``p``."""
    u = rng.random(len(fixes.time))
    lost = np.zeros(len(fixes.time), dtype=bool)
    for a, b, p in losses:
        lost |= (fixes.time >= a) & (fixes.time < b) & (u < p)
    keep = ~lost
    return GnssFixes(time=fixes.time[keep], lla=fixes.lla[keep], pos_sigma=fixes.pos_sigma[keep],
                     vel_n=None if fixes.vel_n is None else fixes.vel_n[keep],
                     vel_sigma=None if fixes.vel_sigma is None else fixes.vel_sigma[keep], source=fixes.source)


def _without_fixes_below_four(fixes: GnssFixes, obs):
    """The fixes at epochs where at least 4 satellites are tracked (a receiver
    cannot fix its position and clock with fewer)."""
    n_vis = np.zeros(len(fixes), dtype=int)
    k = np.searchsorted(obs.time, fixes.time - 1e-6)
    ok = (k < len(obs.time)) & (np.abs(obs.time[np.minimum(k, len(obs.time) - 1)] - fixes.time) < 1e-6)
    n_vis[ok] = obs.n_visible[k[ok]]
    keep = n_vis >= 4
    sel = lambda a: None if a is None else a[keep]  # noqa: E731
    out = GnssFixes(time=fixes.time[keep], lla=fixes.lla[keep], pos_sigma=fixes.pos_sigma[keep],
                    vel_n=sel(fixes.vel_n), vel_sigma=sel(fixes.vel_sigma))
    return out


def constellation(name: str, systems=("G",)):
    """The nominal constellation a scenario names (GPS's ``name``), with the other ``systems``'
    nominal constellations when it lists more than GPS (a MultiConstellation)."""
    from ..gnss.constellation import MultiConstellation, NominalConstellation
    gps = NominalConstellation.gps({"gps24": 4, "gps30": 5}[name])
    if tuple(systems) == ("G",):
        return gps
    return MultiConstellation.of(tuple(systems), gps=gps)


def system_offsets(s) -> dict:
    """``[gnss.satellites]``'s true inter-system offsets as system code -> [m]."""
    from ..gnss.constellation import _CODES
    return {_CODES[letter]: float(v) for letter, v in zip(s.systems[1:], s.system_offsets)}


def simulate_satellites(sc: Scenario, truth: Trajectory, streams: Streams, source=None):
    """Raw observables of a scenario with ``[gnss.satellites]``.

    Streams: ``clock`` draws the true initial receiver clock (spread
    ``init.clock_sigma``; the filters start from zero), ``satellites`` the
    clock walk, the observable noise and the ambiguities.
    """
    from ..config.loader import observable_noise
    from ..gnss.observables import SatelliteOutage, simulate_observables
    g, s = sc.gnss, sc.gnss.satellites
    clock0 = streams.get("clock").standard_normal(2) * np.asarray(sc.init.clock_sigma)
    pr_noise, rr_noise, cp_noise = observable_noise(sc, source)
    outs = [SatelliteOutage(o.window[0], o.window[1], tuple(o.prns), o.keep, o.fraction) for o in s.outages]
    return simulate_observables(
        truth, constellation(s.constellation, s.systems), g.rate, np.asarray(g.lever_arm), s.mask,
        s.pseudorange_sigma, s.range_rate_sigma, s.carrier_sigma,
        (s.clock_bias_noise ** 2, s.clock_drift_noise ** 2), tuple(clock0),
        streams.get("satellites"), outages=tuple(tuple(o) for o in g.outages),
        satellite_outages=outs, pseudorange_noise=pr_noise, range_rate_noise=rr_noise,
        carrier_noise=cp_noise, system_offsets=system_offsets(s) if len(s.systems) > 1 else None)


def initial_estimate(truth: Trajectory, sc: Scenario, rng: np.random.Generator) -> InitialState:
    """Truth at the start plus a draw of the configured 1-sigma errors."""
    ic = sc.init
    s_att, s_vel, s_pos = (np.asarray(v) for v in (ic.attitude_sigma, ic.velocity_sigma, ic.position_sigma))
    phi = rng.standard_normal(3) * s_att
    dv = rng.standard_normal(3) * s_vel
    dr = rng.standard_normal(3) * s_pos
    # Estimate = truth - error (dx = x_true - x_est).
    q = quat_multiply(rotvec_to_quat(-phi), truth.q_nb[0])
    lla = displace(truth.lla[0], -dr)
    nav = np.concatenate([q, truth.v_n[0] - dv, lla])
    return InitialState(time=float(truth.time[0]), nav=nav, sigma_att=s_att, sigma_vel=s_vel,
                        sigma_pos=s_pos, sigma_clock=np.asarray(ic.clock_sigma, dtype=float))
