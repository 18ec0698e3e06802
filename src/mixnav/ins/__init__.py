"""Strapdown INS: mechanization kernels, IMU error models, error-state layouts.

``_kernels``        numba mechanization (one IMU step, a block of steps)
``_error_kernels``  numba error-state F, discretisation, covariance propagation
``error_model``     named state layouts (15, 17, 21, 23) and the noise model they use
``imu_model``       IMU error models with datasheet-unit grades
``mechanization``   the public, validated entry point for free-inertial runs
"""
