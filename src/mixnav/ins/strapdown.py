"""The strapdown INS as the engine's motion model (error-state family).

A motion model gives the engine three things (see :mod:`mixnav.engine`):

- ``propagate``: mechanize a block of IMU increments from the nominal state
  and give this block's error-state transition ``Phi`` and noise ``Qd``
  (written into the ``work`` scratch), optionally propagating one covariance
  in the same compiled call (the fast path the one-Gaussian EKF uses);
- ``inject``: apply an error estimate to the nominal state (closed-loop
  feedback: ``C_new = exp([phi x]) C``, ``v += dv``, position moved by ``dr``,
  sensor and clock estimates incremented, auxiliary blocks added);
- ``initial_covariance``: P0 from an :class:`~mixnav.data.InitialState`.

The ensemble family (UKF, DD2, GMPF) uses the member seam
(:class:`~mixnav.engine.protocols.MotionModel`): ``member_states`` (error states
``D`` (N, n) about a nominal as full states), ``propagate_members`` (members
about the nominal before a step, propagated over it and differenced back against
the propagated nominal, one compiled call: :mod:`mixnav.ins._batch_kernels`),
``difference_members`` and ``member_rates``. ``propagate_batch`` mechanizes raw
full states. ``particle_kernels`` gives the particle filter its fused strapdown kernels
(:mod:`mixnav.ins._particle_kernels`). A vehicle dead-reckoning or constant-velocity model is another
class with the same methods (:mod:`mixnav.motion`).
"""

from __future__ import annotations

import numpy as np

from ..data import InitialState, OdometryIncrements
from ._batch_kernels import difference_members, member_navs, propagate_members
from ._error_kernels import apply_feedback, mechanize_batch, propagate_block
from ._particle_kernels import PARALLEL as _PARTICLES_PARALLEL
from ._particle_kernels import SERIAL as _PARTICLES_SERIAL
from .error_model import ClockModel, StateLayout, body_noise, process_noise
from .imu_model import ImuErrorModel

_WARM: set = set()


class StrapdownMotion:
    """Strapdown mechanization in NED with the error-state model of ``layout``.

    Parameters
    ----------
    layout : StateLayout
        The error states carried (and their process noise).
    imu_model : ImuErrorModel
        The filter's model of the IMU (sets Q and the initial sensor sigma).
    clock : ClockModel, optional
        Receiver clock noise (layouts with a clock block).

    Attributes
    ----------
    qc : ndarray (n,)
        Diagonal continuous noise density (:func:`~mixnav.ins.error_model.process_noise`).
    qb : ndarray (6,)
        White noise per body axis (:func:`~mixnav.ins.error_model.body_noise`; zero
        unless ARW or VRW differ between the axes).
    tau : ndarray (4,)
        Correlation times of the sensor biases and scale factors [s].
    sensor_sigma0 : ndarray (n,)
        Initial 1-sigma of the sensor (and auxiliary) states.
    """

    def __init__(self, layout: StateLayout, imu_model: ImuErrorModel, clock: ClockModel | None = None):
        self.layout = layout
        self.imu_model = imu_model
        self.clock = clock
        self.qc, self.tau, self.sensor_sigma0 = process_noise(layout, imu_model, clock)
        self.qb = body_noise(imu_model)
        self.layout_array = layout.as_array()
        self._tau = np.asarray(self.tau, dtype=float)
        self._scratch = {}   # member count -> (navs, prevs, sensors) of the batch kernel

    def check_inputs(self, inputs) -> None:
        """The strapdown INS is driven by IMU increments, not by odometry."""
        if isinstance(inputs, OdometryIncrements):
            from ..errors import ArgumentError
            raise ArgumentError("the strapdown INS is driven by IMU increments, got OdometryIncrements "
                                "(use mixnav.motion.DeadReckoningMotion)", argument="imu")

    def initial_covariance(self, init: InitialState) -> np.ndarray:
        """Diagonal P0 (n, n) from the initial sigmas and the sensor model."""
        lay = self.layout
        s = self.sensor_sigma0.copy()
        s[lay.att] = init.sigma_att
        s[lay.vel] = init.sigma_vel
        s[lay.pos] = init.sigma_pos
        if lay.clk >= 0:
            s[lay.clk:lay.clk + 2] = init.sigma_clock
        return np.diag(s ** 2)

    def propagate(self, nav, prev, sensor, dtheta, dvel, dt, P, work) -> float:
        """Mechanize one block in place and fill ``work`` = ``[F, Phi, Qd, scratch]``.

        ``P`` (n, n) is propagated in place in the same compiled call
        (:func:`~mixnav.ins._error_kernels.propagate_block`); an estimator that
        carries no single covariance passes a zeroed scratch. Returns the
        block length ``T`` [s] (0: nothing was propagated).
        """
        return propagate_block(nav, prev, sensor, dtheta, dvel, dt, P, self.qc, self.layout_array, self.tau,
                               work, self.qb)

    def inject(self, nav, sensor, clock, aux, dx) -> None:
        """Feed the error estimate ``dx`` (n,) back into the nominal state (in place)."""
        apply_feedback(nav, sensor, clock, dx, self.layout_array)
        for name, sl in self.layout.aux:
            aux[name] += dx[sl]

    def propagate_batch(self, navs, prevs, sensors, dtheta, dvel, dt) -> None:
        """Mechanize a block of raw increments from a batch of N full states, in place, in
        one compiled call (:func:`~mixnav.ins._error_kernels.mechanize_batch`): the motion
        model of the ensemble estimators (UKF sigma points, particles).

        ``navs`` (N, 10), ``prevs`` (N, 6) previous compensated increments, ``sensors``
        (N, 12) sensor-error states per member; ``dtheta``, ``dvel`` (K, 3) [rad, m/s],
        ``dt`` (K,) [s].
        """
        mechanize_batch(navs, prevs, sensors, dtheta, dvel, dt)

    # --- the ensemble seam: members are error states D (N, n) about a nominal ----------------
    def member_states(self, nav, sensor, D, navs) -> None:
        """The members ``D`` (N, n) about ``nav`` as full navigation states ``navs`` (N, 10)
        (the feedback map on copies of ``nav``; the sensor part of a member is its deviation,
        which :meth:`member_rates` applies, so ``sensor`` is not needed here)."""
        member_navs(nav, D, self.layout_array, navs)

    def member_rates(self, w_b, D) -> np.ndarray:
        """The body rate (N, 3) [rad/s] each member sees: ``w_b`` less its gyro-bias deviation."""
        return np.asarray(w_b, dtype=float) - D[:, 9:12]

    def propagate_members(self, inputs, D, substeps, T, Dn) -> None:
        """Members ``D`` (N, n) about the nominal before a step (``inputs``, a
        :class:`~mixnav.engine.protocols.StepInputs`) mechanized over its IMU block (merged
        into at most ``substeps`` sub-intervals; 0: every increment) with a reference (the
        nominal, mechanized the same way), and differenced back: ``Dn`` (N, n) are their
        error states about the propagated reference (sensor deviations decayed by their
        Gauss-Markov model over ``T`` [s], clock bias moved by drift ``T``). One compiled
        call (:func:`~mixnav.ins._batch_kernels.propagate_members`)."""
        N = D.shape[0]
        scr = self._scratch.get(N)
        if scr is None:
            scr = self._scratch[N] = (np.empty((N + 1, 10)), np.empty((N + 1, 6)), np.empty((N + 1, 12)))
        propagate_members(inputs.nav0, inputs.prev0, inputs.sensor, D, inputs.dtheta, inputs.dvel, inputs.dt,
                          substeps, self.layout_array, self._tau, T, scr[0], scr[1], scr[2], Dn)

    def difference_members(self, navs, ref, D, Dn) -> None:
        """``Dn`` (N, n): the full states ``navs`` (N, 10) as error states about ``ref`` (10,)
        (rotation vector, velocity, NED metres); the other blocks copied from ``D`` (N, n).
        The inverse of :meth:`member_states`: ``difference(member_states(nav, D), nav) == D``."""
        difference_members(navs, ref, D, Dn, self.layout_array, np.full(4, np.inf), 0.0)

    @staticmethod
    def particle_kernels(parallel: bool = False):
        """The particle filter's compiled strapdown kernels, serial or parallel (the same
        arithmetic, :mod:`mixnav.ins._particle_kernels`), each one compiled call per use:
        ``step`` (the particles propagated over an IMU block, fused per particle, plus their
        process noise), ``member_navs`` (the particles as full states; a fused measurement
        update is the measurement model's, ``member_update``); ``scratch`` the width of their
        per-particle scratch rows. A static method: the estimator's warm-up needs the set
        before it has a motion model."""
        return _PARTICLES_PARALLEL if parallel else _PARTICLES_SERIAL

    def warm_up(self) -> None:
        """Compile (or load from numba's cache) the kernels for this layout size once per
        process, so measured epoch times are steady-state costs, not compilation."""
        n = self.layout.n
        if n in _WARM:
            return
        nav = np.array([1.0, 0, 0, 0, 0, 0, 0, 0.5, 0.5, 0.0])
        one = np.zeros((1, 3))
        propagate_block(nav, np.zeros(6), np.zeros(12), one, one, np.full(1, 0.01), np.eye(n),
                        np.zeros(n), self.layout_array, np.full(4, np.inf), np.empty((4, n, n)), np.ones(6))
        apply_feedback(nav, np.zeros(12), np.zeros(2), np.zeros(n), self.layout_array)
        _WARM.add(n)
        if "members" not in _WARM:   # the ensemble seam's kernels (any layout size)
            N = 3
            D = np.zeros((N, n))
            navs = np.empty((N, 10))
            propagate_members(nav, np.zeros(6), np.zeros(12), D, one, one, np.full(1, 0.01), 1, self.layout_array,
                              np.full(4, np.inf), 0.01, np.empty((N + 1, 10)), np.empty((N + 1, 6)),
                              np.empty((N + 1, 12)), np.empty((N, n)))
            member_navs(nav, D, self.layout_array, navs)
            difference_members(navs, nav, D, np.empty((N, n)), self.layout_array, np.full(4, np.inf), 0.0)
            _WARM.add("members")
