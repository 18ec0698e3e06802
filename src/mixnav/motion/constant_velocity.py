"""A constant-velocity motion model for GNSS-only users, on the same engine.

Nominal: position (``nav[7:10]``) and NED velocity (``nav[4:7]``); attitude is not
modelled (``q_nb`` stays as initialised). Per step of ``T`` seconds the position
moves by ``v_n T`` (NED metres, the INS feedback's convention) and the velocity
is held. Error state ``[dr_n, dr_e, dr_d, dv_n, dv_e, dv_d]`` (position first:
the core's ``position`` and ``velocity`` blocks), then the clock and auxiliary
blocks::

    Phi = [[I, T I], [0, I]],
    Qd  = q [[T^3/3, T^2/2], [T^2/2, T]]   per axis (white acceleration, density
                                            q = accel_sigma^2 horizontally, vertical_accel_sigma^2 down)

It is driven by :func:`clock_ticks` (increments that carry only time).

The ensemble seam (:class:`~mixnav.engine.protocols.MotionModel`): a member ``D_j``
is the nominal with its position moved by ``D_j``'s NED metres and ``D_j``'s velocity
added; it moves as the nominal does, and its propagated error state is its position
and velocity difference from the propagated nominal (numpy, vectorised over members).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..data import ImuData, InitialState
from ..errors import ArgumentError
from ..ins.error_model import ClockModel, StateBlock, StateLayout
from ._common import (clock_blocks, initial_diagonal, move_position, move_positions, pass_clock_and_aux,
                      position_difference, propagate_covariance)

CV_CORE = (
    StateBlock("position", 3, "model", "nav", labels=("dr_n", "dr_e", "dr_d")),
    StateBlock("velocity", 3, "model", "nav", labels=("dv_n", "dv_e", "dv_d")),
)


def clock_ticks(start: float, end: float, interval: float) -> ImuData:
    """Increments that carry only time, every ``interval`` [s] from ``start`` to ``end``
    [s] (the last one ends at ``end``): what drives :class:`ConstantVelocityMotion`."""
    if not (math.isfinite(start) and math.isfinite(end) and end > start):
        raise ArgumentError(f"need start < end, got {start}, {end}", argument="end")
    if not (interval > 0.0):
        raise ArgumentError(f"must be positive, got {interval}", argument="interval")
    t = np.arange(start + interval, end, interval)
    t = np.append(t[t < end - 1e-9], end)
    dt = np.diff(np.concatenate([[start], t]))
    z = np.zeros((len(t), 3))
    return ImuData(time=t, dt=dt, dtheta=z, dvel=z.copy(), source="clock ticks")


@dataclass(frozen=True)
class ConstantVelocityNoise:
    """White-acceleration densities: ``accel_sigma`` [m/s^2/sqrt(Hz)] horizontal,
    ``vertical_accel_sigma`` vertical."""

    accel_sigma: float = 1.0
    vertical_accel_sigma: float = 0.3

    def __post_init__(self):
        for name in ("accel_sigma", "vertical_accel_sigma"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ArgumentError(f"must be finite and >= 0, got {v}", argument=name)


def constant_velocity_layout(clock: bool = True, system_offsets: int = 0, offset_sigma0: float = 100.0,
                             offset_walk: float = 0.01) -> StateLayout:
    """Position, velocity, then the receiver clock and ``system_offsets`` inter-system
    offsets (auxiliary block ``system_offset`` [m])."""
    blocks = ["clock"] if clock else []
    if system_offsets:
        blocks.append(StateBlock("system_offset", int(system_offsets), "random_walk", "aux", offset_sigma0,
                                 offset_walk, tuple(f"isb_{i}" for i in range(int(system_offsets)))))
    return StateLayout("constant-velocity", blocks, core=CV_CORE)


class ConstantVelocityMotion:
    """Constant velocity in NED (module docstring).

    Parameters
    ----------
    layout : StateLayout
        From :func:`constant_velocity_layout`.
    noise : ConstantVelocityNoise
    clock : ClockModel, optional
    """

    def __init__(self, layout: StateLayout, noise: ConstantVelocityNoise = ConstantVelocityNoise(),
                 clock: ClockModel | None = None):
        if layout.is_ins or layout.vel is None or layout.att is not None:
            raise ArgumentError("needs a constant-velocity layout (constant_velocity_layout())",
                                argument="layout")
        self.layout = layout
        self.noise = noise
        self.clock = clock or ClockModel()
        self._I = np.eye(layout.n)

    def check_inputs(self, inputs) -> None:
        """Any increments: only their times are used."""

    def initial_covariance(self, init: InitialState) -> np.ndarray:
        return initial_diagonal(self.layout, {"position": init.sigma_pos, "velocity": init.sigma_vel,
                                              "clock": init.sigma_clock})

    def propagate(self, nav, prev, sensor, dtheta, dvel, dt, P, work) -> float:
        T = float(np.sum(dt))
        F, Phi, Qd = work[0], work[1], work[2]
        F[:] = 0.0
        Phi[:] = self._I
        Qd[:] = 0.0
        if T <= 0.0:
            return 0.0
        p, v = self.layout.pos.start, self.layout.vel.start
        move_position(nav, nav[4] * T, nav[5] * T, nav[6] * T)
        qh, qv = self.noise.accel_sigma ** 2, self.noise.vertical_accel_sigma ** 2
        for i in range(3):
            q = qh if i < 2 else qv
            F[p + i, v + i] = 1.0
            Phi[p + i, v + i] = T
            Qd[p + i, p + i] = q * T ** 3 / 3.0
            Qd[p + i, v + i] = Qd[v + i, p + i] = q * T ** 2 / 2.0
            Qd[v + i, v + i] = q * T
        clock_blocks(self.layout, self.clock, T, Phi, Qd)
        prev[:] = 0.0
        propagate_covariance(P, Phi, Qd)
        return T

    def inject(self, nav, sensor, clock, aux, dx) -> None:
        lay = self.layout
        p, v = lay.pos.start, lay.vel.start
        move_position(nav, dx[p], dx[p + 1], dx[p + 2])
        nav[4:7] += dx[v:v + 3]
        if lay.clk >= 0:
            clock[0] += dx[lay.clk]
            clock[1] += dx[lay.clk + 1]
        for name, sl in lay.aux:
            aux[name] += dx[sl]

    # --- the ensemble seam (module docstring) --------------------------------------------------
    def member_states(self, nav, sensor, D, navs) -> None:
        """The members ``D`` (N, n) about ``nav`` as full states ``navs`` (N, 10)."""
        p, v = self.layout.pos.start, self.layout.vel.start
        navs[:] = nav
        move_positions(navs, D[:, p], D[:, p + 1], D[:, p + 2])
        navs[:, 4:7] += D[:, v:v + 3]

    def member_rates(self, w_b, D) -> np.ndarray:
        """No body rates are modelled: every member sees ``w_b``."""
        return np.ascontiguousarray(np.broadcast_to(np.asarray(w_b, dtype=float), (D.shape[0], 3)))

    def propagate_members(self, inputs, D, substeps, T, Dn) -> None:
        """Members about the nominal before the step moved by their velocities over ``T`` [s]
        with the nominal (a reference, moved the same way), differenced back into ``Dn``.
        ``substeps`` is not used (one move per step)."""
        N = D.shape[0]
        Dz = np.zeros((N + 1, D.shape[1]))
        Dz[:N] = D
        navs = np.empty((N + 1, 10))
        self.member_states(inputs.nav0, inputs.sensor, Dz, navs)
        if T > 0.0:
            move_positions(navs, navs[:, 4] * T, navs[:, 5] * T, navs[:, 6] * T)
        self.difference_members(navs[:N], navs[N], D, Dn)
        pass_clock_and_aux(self.layout, D, Dn, T)

    def difference_members(self, navs, ref, D, Dn) -> None:
        """``Dn`` (N, n): the full states ``navs`` (N, 10) as error states about ``ref`` (position
        in NED metres, velocity); the other blocks copied from ``D``."""
        p, v = self.layout.pos.start, self.layout.vel.start
        Dn[:] = D
        Dn[:, p:p + 3] = position_difference(navs, ref)
        Dn[:, v:v + 3] = navs[:, 4:7] - ref[4:7]

    def warm_up(self) -> None:
        """Nothing to compile (numpy)."""
