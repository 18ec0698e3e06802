"""Method names usable in scenario and dataset files, and how each is built."""

from __future__ import annotations

from ..config.loader import imu_model
from ..config.schema import MethodConfig
from ..errors import ConfigError
from ..ins.error_model import ClockModel, get_layout
from ..ins.imu_model import ImuErrorModel
from ..measurements.loose import LooseGnss
from ..measurements.tdcp import TdcpGnss
from ..measurements.tight import TightGnss
from .ekf import ErrorStateEkf

#: Method type -> one-line description (listed by ``mixnav scenarios``).
METHODS = {
    "loose-ekf": "M1 closed-loop error-state EKF, GNSS position/velocity (loose coupling)",
    "tight-ekf": "M1 closed-loop error-state EKF, pseudorange + Doppler (tight coupling, 17 states)",
    "tdcp-ekf": "M1 closed-loop error-state EKF, pseudorange + TDCP (P1 eqs. 1-4; stochastic cloning "
                "of the previous antenna position and clock)",
}


def build(method: MethodConfig, default_imu: ImuErrorModel, fixes, lever_arm, source=None, index: int = 0,
          observations=None, clock: ClockModel | None = None):
    """The filter and its measurement models for one method of a config.

    The filter models the IMU with the method's own ``imu_grade``/``imu_errors``
    when given, otherwise with ``default_imu`` (the simulated IMU of a
    scenario, or the dataset's IMU model). Tight methods need the raw
    ``observations`` (:class:`mixnav.gnss.observables.GnssObservations`) and
    the receiver ``clock`` model.
    """
    layout = get_layout(method.states)
    model = default_imu
    if method.imu_grade is not None or method.imu_errors is not None:
        model = imu_model(method.imu_grade, method.imu_errors or {}, source,
                          f"methods[{index}].imu_errors", f"methods[{index}].imu_grade")
    if method.type == "loose-ekf":
        ekf = ErrorStateEkf(layout, model, covariance_interval=method.covariance_interval)
        return ekf, [LooseGnss(fixes, lever_arm, layout)]
    if method.type in ("tight-ekf", "tdcp-ekf"):
        if observations is None:
            raise ConfigError(f"method '{method.name}' is tightly coupled but there are no raw "
                              "GNSS observations", file=source, key=f"methods[{index}].type")
        ekf = ErrorStateEkf(layout, model, covariance_interval=method.covariance_interval,
                            clock=clock or ClockModel())
        if method.type == "tdcp-ekf":
            return ekf, [TdcpGnss(observations, lever_arm, layout, clone=method.tdcp_previous == "clone")]
        return ekf, [TightGnss(observations, lever_arm, layout, use_range_rate=method.use_range_rate)]
    raise KeyError(method.type)  # unreachable: the schema admits only known types
