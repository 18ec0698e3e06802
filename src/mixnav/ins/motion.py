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

The ensemble family (UKF, particle filters) uses ``propagate_batch``: the
mechanization of a batch of full states over a block in one compiled call.
A vehicle dead-reckoning or constant-velocity model is another class with the
same methods (:mod:`mixnav.motion`).
"""

from __future__ import annotations

import numpy as np

from ..data import InitialState, OdometryIncrements
from ._error_kernels import apply_feedback, mechanize_batch, propagate_block
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
