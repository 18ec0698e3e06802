"""Filters: the Kalman kernel, IMU/event time alignment, and the filter engines.

``kalman``    pure compiled Kalman correction (Joseph form, Cholesky)
``timing``    split IMU increments at measurement times
``ekf``       the closed-loop error-state EKF engine (M1)
``registry``  method names usable in scenario files
"""
