"""Turn a validated scenario into simulated data for one seeded run."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..attitude import quat_multiply, rotvec_to_quat
from ..config.loader import gnss_noise, imu_model, imu_white_noise
from ..config.schema import (AccelerateSegment, ClimbSegment, Scenario, StaticSegment,
                             TurnSegment, UniformSegment)
from ..data import GnssFixes, ImuData, Trajectory
from ..data import InitialState
from ..ins.imu_model import ImuErrorDraw, ImuErrorModel, corrupt
from .gnss import GnssFixModel, simulate_fixes
from .rng import Streams
from .trajectory import InitialState as TrajectoryStart
from .trajectory import MotionSegment, generate
from ..geodesy.frames import displace


@dataclass(frozen=True)
class SimulatedRun:
    """Everything one seeded run of a scenario needs and knows."""

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


def truth_and_ideal_imu(sc: Scenario, source: str | None = None):
    """The deterministic part of a scenario: truth and ideal increments."""
    tr = sc.trajectory
    start = TrajectoryStart(lla=tuple(tr.start), speed=tr.speed, rpy=tuple(tr.attitude))
    return generate(motion_segments(sc), start, sc.imu.rate, source=source)


def simulate(sc: Scenario, seed: int, source: str | None = None, ideal=None) -> SimulatedRun:
    """Draw one run: IMU errors, GNSS noise and the initial estimation error.

    Streams (independent, from ``seed``): ``imu``, ``gnss``, ``init``.
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
    fixes = simulate_fixes(truth, fix_model, streams.get("gnss"), position_noise=pos_noise,
                           velocity_noise=vel_noise)
    init = initial_estimate(truth, sc, streams.get("init"))
    obs, outages = None, fix_model.outages
    if g.satellites is not None:
        obs = simulate_satellites(sc, truth, streams, source)
        fixes = _without_fixes_below_four(fixes, obs)
        # satellite outages leaving fewer than 4 are windows with no fix: scored like outages
        lost = {tuple(o.window) for o in g.satellites.outages
                if o.keep is not None and o.keep < 4 and o.fraction is None}
        outages = tuple(sorted(set(outages) | lost))
    return SimulatedRun(seed, truth, imu_ideal, imu, draw, model, fixes, init, outages, obs)


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


def constellation(name: str):
    """The nominal constellation a scenario names."""
    from ..gnss.constellation import NominalConstellation
    return NominalConstellation.gps({"gps24": 4, "gps30": 5}[name])


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
        truth, constellation(s.constellation), g.rate, np.asarray(g.lever_arm), s.mask,
        s.pseudorange_sigma, s.range_rate_sigma, s.carrier_sigma,
        (s.clock_bias_noise ** 2, s.clock_drift_noise ** 2), tuple(clock0),
        streams.get("satellites"), outages=tuple(tuple(o) for o in g.outages),
        satellite_outages=outs, pseudorange_noise=pr_noise, range_rate_noise=rr_noise,
        carrier_noise=cp_noise)


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
