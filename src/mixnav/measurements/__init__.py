"""Measurement models: each turns the measurements of an epoch and the nominal
INS state into typed rows ``Rows(z, H, R, kinds, channels)``.

The protocol is :class:`mixnav.measurements.base.MeasurementModel`:
``rows(i, nav, w_b, clock, memory=None)`` returns the innovation ``z``
(measured minus predicted, the error-state convention ``dx = x_true - x_est``),
its Jacobian ``H`` over the error state, the noise ``R``, the registered
observable kind of each row (:mod:`mixnav.measurements.kinds`) and a channel
id per row, or ``None`` when the model has no data at that epoch. Models keep
no state between calls; what a two-epoch model remembers (TDCP, differencing)
is returned by ``remember`` and held by the engine.

Models: :class:`~mixnav.measurements.loose.LooseGnss` (position/velocity fixes),
:class:`~mixnav.measurements.tight.TightGnss` (pseudorange + Doppler),
:class:`~mixnav.measurements.tdcp.TdcpGnss` (pseudorange + TDCP, stochastic clone),
:class:`~mixnav.measurements.differenced.DifferencedMeasurement` (AR(1) differencing
of any model's rows).
"""
