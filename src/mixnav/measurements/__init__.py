"""Measurement models: each turns a measurement and the INS state into ``(z, H, R)``.

A model is a small object with one method, ``measure(epoch, nav, sensor,
w_b)``, returning the innovation ``z`` (measured minus predicted, the
error-state convention ``dx = x_true - x_est``), its Jacobian ``H`` over the
error state and the noise covariance ``R``, or ``None`` when it has no data
at that epoch.
"""
