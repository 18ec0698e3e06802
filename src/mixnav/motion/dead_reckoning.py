"""Land-vehicle dead reckoning from wheel speed and yaw rate, as the engine's motion model.

Nominal state (the engine's ``nav = [q_nb, v_n, lat, lon, h]``): heading
``psi`` in a yaw-only ``q_nb`` (roll and pitch zero: a car on a road), the
velocity ``v_n = (1 + k) s [cos psi, sin psi, 0]`` of the last increment, the
position. The sensor vector holds the speed scale-factor estimate ``k``
(``sensor[0]``) and the yaw-rate bias ``b`` [rad/s] (``sensor[1]``). Per increment
of measured distance ``ds = s dt`` and heading change ``dpsi = w dt``::

    psi_mid = psi + (dpsi - b dt) / 2,   psi <- psi + dpsi - b dt
    r_n     <- r_n + (1 + k) ds [cos psi_mid, sin psi_mid, 0]      (height held)

Error state ``dx = x_true - x_est`` (core, 6 states)::

    [dr_n, dr_e, dr_d  (position, NED metres),  dpsi (heading, rad, about down),
     dk (speed scale),  db (yaw-rate bias, rad/s)]

then the clock (bias [m], drift [m/s]) and auxiliary blocks (an inter-system
clock offset) of the layout. Continuous dynamics (speed ``s``, heading
``psi``, ``c = cos psi``, ``sn = sin psi``)::

    dr_n' = s c dk - (1 + k) s sn dpsi - (1 + k) c n_s + sn n_l
    dr_e' = s sn dk + (1 + k) s c dpsi - (1 + k) sn n_s - c n_l
    dr_d' = n_v,   dpsi' = -db - n_w,   dk' = n_k,   db' = n_b

with white noises: ``n_s`` the wheel speed's (density ``speed_sigma^2 Ts``,
``Ts`` the odometry's sample interval, so a per-sample sigma is the data
sheet's), ``n_l`` lateral slip, ``n_v`` vertical motion (the height is not
driven by the odometry), ``n_w`` the yaw rate's, and the random walks of the
scale and the bias. ``F^3 = 0``, so per increment ``Phi = I + F dt + (F dt)^2 / 2``
exactly for the frozen ``F``; ``Qd = G Qc G^T dt``. Feedback: position moved
by NED metres (the INS convention), heading turned about down (``C_new =
exp([phi x]) C`` with ``phi = [0, 0, dpsi]``), velocity rotated and rescaled,
``k``, ``b``, clock and auxiliary estimates incremented.

The ensemble seam (:class:`~mixnav.engine.protocols.MotionModel`): a member ``D_j`` is
the nominal with that feedback applied (``member_states``); over a step every member
dead-reckons the block's increments with its own heading, scale and bias as the
nominal does, and its propagated error state is its NED position and heading
difference from the nominal dead-reckoned the same way, ``dk`` and ``db`` kept
(random walks), the clock's bias moved by its drift (numpy, vectorised over members;
every increment is integrated: ``substeps`` is not used).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..data import InitialState, OdometryIncrements
from ..errors import ArgumentError
from ..ins.error_model import ClockModel, StateBlock, StateLayout
from ._common import (clock_blocks, initial_diagonal, move_position, move_positions, pass_clock_and_aux,
                      position_difference, propagate_covariance)

#: the dead-reckoning core: position, heading, speed scale, yaw-rate bias
DR_CORE = (
    StateBlock("position", 3, "model", "nav", labels=("dr_n", "dr_e", "dr_d")),
    StateBlock("heading", 1, "model", "nav", labels=("dpsi",)),
    StateBlock("speed_scale", 1, "model", "sensor", labels=("dk",)),
    StateBlock("yaw_rate_bias", 1, "model", "sensor", labels=("db_yaw",)),
)
_SLOTS = {"speed_scale": slice(0, 1), "yaw_rate_bias": slice(1, 2)}


def odometry_increments(time, speed, yaw_rate, source: str | None = None) -> OdometryIncrements:
    """Increments from samples of speed [m/s] and yaw rate [rad/s] at ``time`` [s] (N,).

    Sample ``i`` holds over ``(time[i-1], time[i]]`` (zero-order hold of the newer
    value; the first sample only starts the stream: the result has N - 1
    increments). Errors (:class:`~mixnav.errors.ArgumentError`) for shapes,
    non-finite values or times that do not increase.
    """
    t = np.asarray(time, dtype=float)
    s = np.asarray(speed, dtype=float)
    w = np.asarray(yaw_rate, dtype=float)
    if t.ndim != 1 or s.shape != t.shape or w.shape != t.shape or len(t) < 2:
        raise ArgumentError(f"time, speed and yaw_rate must be 1-D of one length >= 2, got {t.shape}, "
                            f"{s.shape}, {w.shape}", argument="time")
    for name, a in (("time", t), ("speed", s), ("yaw_rate", w)):
        if not np.isfinite(a).all():
            raise ArgumentError(f"has {int((~np.isfinite(a)).sum())} non-finite values", argument=name)
    dt = np.diff(t)
    if (dt <= 0).any():
        raise ArgumentError(f"times must increase: sample {int(np.argmax(dt <= 0)) + 1} is not after the one "
                            "before", argument="time")
    n = len(dt)
    dtheta = np.zeros((n, 3))
    dvel = np.zeros((n, 3))
    dtheta[:, 2] = w[1:] * dt
    dvel[:, 0] = s[1:] * dt
    return OdometryIncrements(time=t[1:].copy(), dt=dt, dtheta=dtheta, dvel=dvel, source=source)


@dataclass(frozen=True)
class DeadReckoningNoise:
    """Noise and initial uncertainty of the dead-reckoning model (SI units).

    ``speed_sigma`` [m/s] and ``yaw_rate_sigma`` [rad/s]: 1-sigma of one odometry
    sample, turned into densities with ``sample_interval`` [s]; ``lateral_sigma``
    [m/s] slip across the vehicle, ``vertical_sigma`` [m/s] unmodelled vertical
    motion (per sample interval as well); ``scale_sigma0`` [-], ``bias_sigma0``
    [rad/s] initial sigmas of the speed scale and the yaw-rate bias,
    ``scale_walk`` [1/sqrt(s)], ``bias_walk`` [rad/s/sqrt(s)] their random walks.
    """

    speed_sigma: float = 0.05
    yaw_rate_sigma: float = 0.002
    sample_interval: float = 0.2
    lateral_sigma: float = 0.1
    vertical_sigma: float = 0.1
    scale_sigma0: float = 0.02
    bias_sigma0: float = 0.002
    scale_walk: float = 1e-4
    bias_walk: float = 1e-5

    def __post_init__(self):
        for name in ("speed_sigma", "yaw_rate_sigma", "sample_interval", "lateral_sigma", "vertical_sigma",
                     "scale_sigma0", "bias_sigma0", "scale_walk", "bias_walk"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0) or (name == "sample_interval" and v <= 0.0):
                raise ArgumentError(f"must be finite and {'positive' if name == 'sample_interval' else '>= 0'}, "
                                    f"got {v}", argument=name)


def dead_reckoning_layout(clock: bool = True, system_offsets: int = 0, offset_sigma0: float = 100.0,
                          offset_walk: float = 0.01) -> StateLayout:
    """The dead-reckoning layout: the 6-state core, then the receiver clock (``clock``) and
    ``system_offsets`` inter-system clock offsets [m] (an auxiliary random-walk block
    ``system_offset``, e.g. GLONASS minus GPS; ``offset_sigma0`` [m],
    ``offset_walk`` [m/sqrt(s)])."""
    blocks = ["clock"] if clock else []
    if system_offsets:
        blocks.append(StateBlock("system_offset", int(system_offsets), "random_walk", "aux", offset_sigma0,
                                 offset_walk, tuple(f"isb_{i}" for i in range(int(system_offsets)))))
    return StateLayout("dead-reckoning", blocks, core=DR_CORE, sensor_slots=_SLOTS)


def heading_of(nav: np.ndarray) -> float:
    """Heading [rad] of a yaw-only ``q_nb`` (``nav[0:4]``)."""
    return 2.0 * math.atan2(nav[3], nav[0])


def set_heading(nav: np.ndarray, psi: float) -> None:
    nav[0], nav[1], nav[2], nav[3] = math.cos(0.5 * psi), 0.0, 0.0, math.sin(0.5 * psi)


def _wrap(a):
    """Angles [rad] into [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class DeadReckoningMotion:
    """Wheel speed + yaw rate dead reckoning (module docstring), driven by
    :class:`OdometryIncrements`.

    Parameters
    ----------
    layout : StateLayout
        From :func:`dead_reckoning_layout`.
    noise : DeadReckoningNoise
    clock : ClockModel, optional
        Receiver clock noise (layouts with a clock block).
    """

    def __init__(self, layout: StateLayout, noise: DeadReckoningNoise = DeadReckoningNoise(),
                 clock: ClockModel | None = None):
        if layout.is_ins or not layout.has("heading"):
            raise ArgumentError("needs a dead-reckoning layout (dead_reckoning_layout())", argument="layout")
        self.layout = layout
        self.noise = noise
        self.clock = clock or ClockModel()
        n = layout.n
        self._I = np.eye(n)
        nz = noise
        ts = nz.sample_interval
        # densities: per-sample sigmas over the sample interval
        self._q = dict(s=nz.speed_sigma ** 2 * ts, w=nz.yaw_rate_sigma ** 2 * ts, lat=nz.lateral_sigma ** 2 * ts,
                       v=nz.vertical_sigma ** 2 * ts, k=nz.scale_walk ** 2, b=nz.bias_walk ** 2)

    def check_inputs(self, inputs) -> None:
        if not isinstance(inputs, OdometryIncrements):
            raise ArgumentError(f"dead reckoning is driven by OdometryIncrements (odometry_increments()), got "
                                f"{type(inputs).__name__}", argument="imu")

    def initial_covariance(self, init: InitialState) -> np.ndarray:
        """P0: ``init.sigma_pos`` (NED, m), ``init.sigma_att[2]`` the heading's [rad], the
        noise model's scale and bias sigmas, ``init.sigma_clock``, auxiliary ``sigma0``."""
        nz = self.noise
        return initial_diagonal(self.layout, {"position": init.sigma_pos, "heading": init.sigma_att[2],
                                              "speed_scale": nz.scale_sigma0, "yaw_rate_bias": nz.bias_sigma0,
                                              "clock": init.sigma_clock})

    def propagate(self, nav, prev, sensor, dtheta, dvel, dt, P, work) -> float:
        """Dead-reckon the block in place, fill ``work = [F, Phi, Qd, -]`` and propagate ``P``
        in place. Returns the block length [s]."""
        n = self.layout.n
        F, Phi, Qd = work[0], work[1], work[2]
        Phi[:] = self._I
        Qd[:] = 0.0
        F[:] = 0.0
        K = len(dt)
        if K == 0:
            return 0.0
        q = self._q
        k, b = sensor[0], sensor[1]
        psi = heading_of(nav)
        T = 0.0
        Fi = np.zeros((n, n))
        Qi = np.zeros((n, n))
        for i in range(K):
            h = float(dt[i])
            ds = float(dvel[i, 0])
            dpsi = float(dtheta[i, 2]) - b * h
            s = ds / h
            pm = psi + 0.5 * dpsi
            c, sn = math.cos(pm), math.sin(pm)
            g = 1.0 + k
            move_position(nav, g * ds * c, g * ds * sn, 0.0)
            psi += dpsi
            # frozen F over the increment (heading at mid-interval)
            Fi[0, 3], Fi[0, 4] = -g * s * sn, s * c
            Fi[1, 3], Fi[1, 4] = g * s * c, s * sn
            Fi[3, 5] = -1.0
            Fh = Fi * h
            Phi_i = self._I + Fh + 0.5 * (Fh @ Fh)
            Qi[:] = 0.0
            # along-track speed noise and lateral slip in the horizontal position
            a_n, a_e = g * c, g * sn
            qs, ql = q["s"], q["lat"]
            Qi[0, 0] = (a_n * a_n * qs + sn * sn * ql) * h
            Qi[1, 1] = (a_e * a_e * qs + c * c * ql) * h
            Qi[0, 1] = Qi[1, 0] = (a_n * a_e * qs - sn * c * ql) * h
            Qi[2, 2] = q["v"] * h
            Qi[3, 3] = q["w"] * h
            Qi[4, 4] = q["k"] * h
            Qi[5, 5] = q["b"] * h
            clock_blocks(self.layout, self.clock, h, Phi_i, Qi)
            Phi[:] = Phi_i @ Phi
            Qd[:] = Phi_i @ Qd @ Phi_i.T + Qi
            F[:] = Fi
            T += h
        set_heading(nav, psi)
        s_last = float(dvel[K - 1, 0]) / float(dt[K - 1])
        g = 1.0 + k
        nav[4], nav[5], nav[6] = g * s_last * math.cos(psi), g * s_last * math.sin(psi), 0.0
        prev[:] = 0.0
        prev[2] = float(dtheta[K - 1, 2]) - b * float(dt[K - 1])
        prev[3] = float(dvel[K - 1, 0])
        propagate_covariance(P, Phi, Qd)
        return T

    def inject(self, nav, sensor, clock, aux, dx) -> None:
        """Feed ``dx`` back (module docstring), in place."""
        lay = self.layout
        move_position(nav, dx[0], dx[1], dx[2])
        d_psi = float(dx[3])
        psi = heading_of(nav) + d_psi
        set_heading(nav, psi)
        k_old = sensor[0]
        sensor[0] += dx[4]
        sensor[1] += dx[5]
        # the velocity follows the heading and the scale
        vn, ve = nav[4], nav[5]
        c, s = math.cos(d_psi), math.sin(d_psi)
        r = (1.0 + sensor[0]) / (1.0 + k_old) if 1.0 + k_old != 0.0 else 1.0
        nav[4], nav[5] = r * (c * vn - s * ve), r * (s * vn + c * ve)
        if lay.clk >= 0:
            clock[0] += dx[lay.clk]
            clock[1] += dx[lay.clk + 1]
        for name, sl in lay.aux:
            aux[name] += dx[sl]

    # --- the ensemble seam (module docstring) --------------------------------------------------
    def member_states(self, nav, sensor, D, navs) -> None:
        """The members ``D`` (N, n) about ``nav`` (and the speed scale ``sensor[0]``) as full
        states ``navs`` (N, 10): :meth:`inject` on copies of ``nav``, vectorised."""
        navs[:] = nav
        move_positions(navs, D[:, 0], D[:, 1], D[:, 2])
        d_psi = D[:, 3]
        psi = heading_of(nav) + d_psi
        navs[:, 0], navs[:, 1], navs[:, 2], navs[:, 3] = np.cos(0.5 * psi), 0.0, 0.0, np.sin(0.5 * psi)
        k = float(sensor[0])
        r = (1.0 + k + D[:, 4]) / (1.0 + k) if 1.0 + k != 0.0 else np.ones(D.shape[0])
        c, s = np.cos(d_psi), np.sin(d_psi)
        vn, ve = nav[4], nav[5]
        navs[:, 4], navs[:, 5] = r * (c * vn - s * ve), r * (s * vn + c * ve)

    def member_rates(self, w_b, D) -> np.ndarray:
        """``w_b`` with each member's yaw-rate bias deviation taken off its heading rate."""
        w = np.array(np.broadcast_to(np.asarray(w_b, dtype=float), (D.shape[0], 3)))
        w[:, 2] -= D[:, 5]
        return w

    def propagate_members(self, inputs, D, substeps, T, Dn) -> None:
        """Members about the nominal before the step dead-reckoned over its increments with a
        reference (the nominal, the same way), differenced back into ``Dn`` (module docstring)."""
        N = D.shape[0]
        Dz = np.zeros((N + 1, D.shape[1]))
        Dz[:N] = D
        navs = np.empty((N + 1, 10))
        nav0, sensor = inputs.nav0, inputs.sensor
        self.member_states(nav0, sensor, Dz, navs)
        psi = heading_of(nav0) + Dz[:, 3]
        g = 1.0 + sensor[0] + Dz[:, 4]
        b = sensor[1] + Dz[:, 5]
        for i in range(len(inputs.dt)):
            h = float(inputs.dt[i])
            ds = float(inputs.dvel[i, 0])
            dpsi = float(inputs.dtheta[i, 2]) - b * h
            pm = psi + 0.5 * dpsi
            move_positions(navs, g * ds * np.cos(pm), g * ds * np.sin(pm), 0.0)
            psi = psi + dpsi
        Dn[:] = D
        Dn[:, 0:3] = position_difference(navs[:N], navs[N])
        Dn[:, 3] = _wrap(psi[:N] - psi[N])
        pass_clock_and_aux(self.layout, D, Dn, T)

    def difference_members(self, navs, ref, D, Dn) -> None:
        """``Dn`` (N, n): the full states ``navs`` (N, 10) as error states about ``ref`` (NED
        metres, heading); the other blocks (scale, bias, clock, auxiliary) copied from ``D``."""
        Dn[:] = D
        Dn[:, 0:3] = position_difference(navs, ref)
        Dn[:, 3] = _wrap(2.0 * np.arctan2(navs[:, 3], navs[:, 0]) - heading_of(ref))

    def warm_up(self) -> None:
        """Nothing to compile (numpy)."""
