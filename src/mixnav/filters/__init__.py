"""Estimators on the engine, and the filters users run.

``kalman``       pure compiled Kalman correction (Joseph form, Cholesky)
``ekf``          M1: ``KalmanEstimator`` and the ``ErrorStateEkf`` filter
``robust_adaptive`` M2: IGG-III weights + Yang's adaptive factor
``gmekf``        M3-M5: the bank of Gaussian components (``BankEstimator``)
``colored``      M6: the bank with AR(1) process-noise states and differencing
``sage_husa``    Sage-Husa adaptive EKF (a variance scale per observable kind)
``student_t``    Student-t filter with VB noise scales (Huang et al. 2017)
``vb_akf``       VB-adaptive EKF (an inverse-Gamma noise variance per channel)
``ukf``, ``dd2``, ``particle``, ``gmpf``, ``epoch_mixture``, ``imm``, ``em_bias``: the others
``registry``     the estimator registry (each estimator registers itself; plug-ins by entry point)
``facade``       ``Filter``: the strapdown INS + any registered estimator + the engine
"""
