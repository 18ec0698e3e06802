"""Estimators on the engine, and the filters users run.

``kalman``       pure compiled Kalman correction (Joseph form, Cholesky)
``ekf``          M1: ``KalmanEstimator`` and the ``ErrorStateEkf`` filter
``robust``       M2: IGG-III weights + Yang's adaptive factor
``gmekf``        M3-M5: the bank of Gaussian components (``BankEstimator``)
``colored``      M6: the bank with AR(1) process-noise states and differencing
``online``       M4 online re-learning of the measurement mixtures
``sage_husa``    Sage-Husa adaptive EKF (a variance scale per observable kind)
``registry``     the estimator registry (each estimator registers itself; plug-ins by entry point)
``facade``       ``Filter``: the strapdown INS + any registered estimator + the engine
``catalog``      the old catalogue: a view of the registry
"""
