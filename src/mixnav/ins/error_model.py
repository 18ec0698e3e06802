"""Named error-state layouts and the process noise they use.

A layout fixes which error states a filter carries and where; the filters
and measurement models address states by these names, never by bare
numbers. The state order inside each block is N, E, D for navigation errors
and x, y, z (body) for sensor errors; see :mod:`mixnav.ins._error_kernels`
for the dynamics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from .imu_model import ImuErrorModel


@dataclass(frozen=True)
class StateLayout:
    """Positions of the error-state blocks.

    Attributes
    ----------
    name : str
    n : int
        Number of states.
    sg, sa, clk : int
        First index of the gyro/accelerometer scale-factor blocks and of the
        clock block (bias [m], drift [m/s]); -1 when absent.
    """

    name: str
    n: int
    sg: int = -1
    sa: int = -1
    clk: int = -1

    att = slice(0, 3)
    vel = slice(3, 6)
    pos = slice(6, 9)
    bg = slice(9, 12)
    ba = slice(12, 15)

    def as_array(self) -> np.ndarray:
        """``[n, i_bg, i_ba, i_sg, i_sa, i_clk]`` for the compiled kernels."""
        return np.array([self.n, 9, 12, self.sg, self.sa, self.clk], dtype=np.int64)

    def labels(self) -> list[str]:
        """One short label per state, in order (for tables and plots)."""
        lab = ["phi_n", "phi_e", "phi_d", "dv_n", "dv_e", "dv_d", "dr_n", "dr_e", "dr_d",
               "bg_x", "bg_y", "bg_z", "ba_x", "ba_y", "ba_z"]
        extra = {self.sg: ["sg_x", "sg_y", "sg_z"], self.sa: ["sa_x", "sa_y", "sa_z"],
                 self.clk: ["clock_bias", "clock_drift"]}
        for start in sorted(k for k in extra if k >= 0):
            lab += extra[start]
        return lab


LAYOUTS: dict[int, StateLayout] = {
    15: StateLayout("ins15", 15),
    17: StateLayout("ins15+clock", 17, clk=15),
    21: StateLayout("ins15+scale", 21, sg=15, sa=18),
    23: StateLayout("ins15+scale+clock", 23, sg=15, sa=18, clk=21),
}


def get_layout(n_states: int) -> StateLayout:
    """The layout with ``n_states`` states (15, 17, 21 or 23)."""
    try:
        return LAYOUTS[int(n_states)]
    except (KeyError, ValueError):
        raise ConfigError(f"no error-state layout with {n_states!r} states; choose one of "
                          f"{sorted(LAYOUTS)}", key="states") from None


@dataclass(frozen=True)
class ClockModel:
    """Two-state receiver clock: white frequency and random-walk frequency noise.

    ``q_bias`` [m^2/s] drives the bias, ``q_drift`` [m^2/s^3] the drift.
    """

    q_bias: float = 0.1
    q_drift: float = 0.01


def process_noise(layout: StateLayout, imu: ImuErrorModel, clock: ClockModel | None = None):
    """Continuous noise density ``qc`` (diagonal), correlation times, and P0 of sensor states.

    Returns
    -------
    qc : ndarray (n,)
        Spectral densities: ARW^2 and VRW^2 on the attitude and velocity
        errors; ``2 sigma^2 / tau + walk^2`` on the biases (Gauss-Markov
        plus random walk); zero on the scale factors (constants); the clock
        densities.
    tau : ndarray (4,)
        Correlation times of bg, ba, sg, sa [s].
    sensor_sigma0 : ndarray (n,)
        Initial 1-sigma of the sensor-error states (zero elsewhere): turn-on
        bias and in-run instability combined; scale-factor sigma.
    """
    n = layout.n
    qc = np.zeros(n)
    s0 = np.zeros(n)
    qc[layout.att] = imu.arw ** 2
    qc[layout.vel] = imu.vrw ** 2
    gm = lambda s, t: 2.0 * s * s / t if np.isfinite(t) else 0.0  # noqa: E731
    qc[layout.bg] = gm(imu.gyro_bias_instability, imu.gyro_bias_tau) + imu.gyro_bias_walk ** 2
    qc[layout.ba] = gm(imu.accel_bias_instability, imu.accel_bias_tau) + imu.accel_bias_walk ** 2
    s0[layout.bg] = np.hypot(imu.gyro_bias, imu.gyro_bias_instability)
    s0[layout.ba] = np.hypot(imu.accel_bias, imu.accel_bias_instability)
    tau = np.array([imu.gyro_bias_tau if imu.gyro_bias_instability > 0 else np.inf,
                    imu.accel_bias_tau if imu.accel_bias_instability > 0 else np.inf,
                    np.inf, np.inf])
    if layout.sg >= 0:
        s0[layout.sg:layout.sg + 3] = imu.gyro_scale
        s0[layout.sa:layout.sa + 3] = imu.accel_scale
    if layout.clk >= 0:
        clock = clock or ClockModel()
        qc[layout.clk] = clock.q_bias
        qc[layout.clk + 1] = clock.q_drift
    return qc, tau, s0
