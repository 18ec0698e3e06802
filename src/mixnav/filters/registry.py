"""Method names usable in scenario files, and how each is built."""

from __future__ import annotations

from ..config.loader import imu_model
from ..config.schema import MethodConfig
from ..ins.error_model import get_layout
from ..measurements.loose import LooseGnss
from .ekf import ErrorStateEkf

#: Method type -> one-line description (listed by ``mixnav scenarios``).
METHODS = {
    "loose-ekf": "M1 closed-loop error-state EKF, GNSS position/velocity (loose coupling)",
}


def build(method: MethodConfig, run, lever_arm, source=None):
    """The filter and its measurement models for one method of a scenario.

    The filter models the IMU with the method's own grade/errors when given,
    otherwise with the scenario's true IMU model.
    """
    if method.type == "loose-ekf":
        layout = get_layout(method.states)
        model = run.imu_model
        if method.imu_grade is not None or method.imu_errors is not None:
            model = imu_model(method.imu_grade, method.imu_errors or {}, source,
                              f"methods.{method.name}.imu_errors", f"methods.{method.name}.imu_grade")
        ekf = ErrorStateEkf(layout, model, covariance_interval=method.covariance_interval)
        return ekf, [LooseGnss(run.fixes, lever_arm, layout)]
    raise KeyError(method.type)  # unreachable: the schema admits only known types
