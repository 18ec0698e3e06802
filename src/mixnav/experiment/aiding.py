"""Land-vehicle aiding of a config's methods: the ``[aiding]`` table -> measurement models.

One :class:`AidingInputs` per run holds what the aiding models of every method
share (the IMU, the fixes, the odometer samples and the stillness detection,
computed once); :func:`method_layout` adds the installation states a method
estimates to its layout, and :func:`aiding_models` builds the models a method
lists in ``aiding = [...]``. Errors name the config key.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..config.aiding_schema import AidingConfig, ZuptConfig
from ..config.method_schema import MethodConfig
from ..data import GnssFixes, ImuData, OdometerData
from ..errors import ConfigError
from ..ins.error_model import StateLayout, get_layout
from ..measurements.loose import gnss_lever_block, time_offset_block
from ..measurements.stillness import Stillness, detect_still
from ..measurements.vehicle import (NonHolonomic, Odometer, ZeroAngularRate, ZeroVelocity, mean_specific_force,
                                    mounting_block, odometer_scale_block)


@dataclass
class AidingInputs:
    """What the aiding models of one run share.

    ``start``/``end``: the filtered span [s]; ``odometer``: the samples (a dataset's
    file, or the simulated odometer); ``stillness``: computed on first use.
    """

    config: AidingConfig | None
    imu: ImuData
    fixes: GnssFixes | None
    start: float
    end: float
    odometer: OdometerData | None = None
    source: str | None = None
    _still: Stillness | None = field(default=None, repr=False)

    @property
    def stillness(self) -> Stillness:
        if self._still is None:
            z = self.config.zupt if self.config is not None and self.config.zupt is not None else None
            if z is None:
                z = ZuptConfig()
            self._still = detect_still(self.imu, window=z.window, accel_std=z.accel_std, gyro_rate=z.gyro_rate,
                                       fixes=self.fixes, gnss_speed=z.gnss_speed, min_duration=z.min_duration,
                                       odometer=self.odometer, accel_drift=z.accel_drift)
        return self._still

    def summary(self) -> dict:
        """Counts for metrics.json: the still stretches found and the thresholds used."""
        if self._still is None:
            return {}
        s = self._still
        return {"still_intervals": int(len(s.intervals)), "still_time_s": s.still_time_s,
                "still_settings": s.settings}


def _need(cfg, name: str, method: MethodConfig, index: int, source):
    if cfg is None or getattr(cfg, name) is None:
        raise ConfigError(f"method '{method.name}' uses {name} aiding but the file has no [aiding.{name}] table",
                          file=source, key=f"methods[{index}].aiding")
    return getattr(cfg, name)


def method_layout(method: MethodConfig, inputs: AidingInputs | None, source=None, index: int = 0) -> StateLayout:
    """The method's error-state layout (``states``) plus the installation states it estimates."""
    base = get_layout(method.states)
    if not method.estimate:
        return base
    cfg = inputs.config if inputs is not None else None
    blocks = list(base.blocks[5:])
    if len(set(method.estimate)) != len(method.estimate):
        raise ConfigError(f"a state is listed twice: {method.estimate}", file=source,
                          key=f"methods[{index}].estimate")
    for e in method.estimate:
        if e == "mounting":
            if not ({"nhc", "odometer"} & set(method.aiding)):
                raise ConfigError("the mounting is observed by NHC or the odometer: add one to the method's aiding",
                                  file=source, key=f"methods[{index}].estimate")
            blocks.append(mounting_block(cfg.mounting_sigma))
        elif e == "odometer_scale":
            if "odometer" not in method.aiding:
                raise ConfigError("an odometer scale state needs odometer aiding", file=source,
                                  key=f"methods[{index}].estimate")
            blocks.append(odometer_scale_block(cfg.odometer.scale_sigma))
        elif e in ("gnss_lever", "imu_time_offset"):
            if method.type != "loose-ekf":
                raise ConfigError(f"{e} is estimated by the loose GNSS model only (method type 'loose-ekf')",
                                  file=source, key=f"methods[{index}].estimate")
            c = cfg if cfg is not None else AidingConfig()
            blocks.append(gnss_lever_block(c.gnss_lever_sigma) if e == "gnss_lever"
                          else time_offset_block(c.time_offset_sigma, c.time_offset_walk))
    return StateLayout(base.name + "+" + "+".join(method.estimate), blocks)


def aiding_models(method: MethodConfig, layout: StateLayout, inputs: AidingInputs | None, source=None,
                  index: int = 0) -> list:
    """The aiding measurement models a method lists (``aiding = [...]``)."""
    if not method.aiding:
        return []
    cfg = inputs.config if inputs is not None else None
    key = f"methods[{index}].aiding"
    models = []
    needs_frame = {"nhc", "odometer"} & set(method.aiding)
    if needs_frame and (cfg is None or cfg.vehicle_mounting is None):
        raise ConfigError(f"{' and '.join(sorted(needs_frame))} need a vehicle frame: set aiding.vehicle_mounting "
                          "(roll, pitch, yaw of the IMU body frame in the vehicle: x forward, y right, z down)",
                          file=source, key=key)
    span = (inputs.start, inputs.end)
    for name in method.aiding:
        c = _need(cfg, name, method, index, source)
        if name == "nhc":
            t = np.arange(np.floor(span[0] * c.rate) / c.rate + 1.0 / c.rate, span[1] + 1e-9, 1.0 / c.rate)
            # the suspension pitch's forward acceleration: the specific force over the 0.5 s
            # before each epoch (the span over which the gain is measured: docs/aiding.md)
            f = mean_specific_force(inputs.imu, t, 0.5) if c.pitch_per_accel != 0.0 else None
            models.append(NonHolonomic(t, layout, cfg.vehicle_mounting, cfg.vehicle_point, np.asarray(c.sigma),
                                       c.min_speed, c.pitch_per_accel, f))
        elif name == "odometer":
            if inputs.odometer is None:
                raise ConfigError("odometer aiding needs odometer samples: a dataset's aiding.odometer.file, or "
                                  "a scenario's simulated [odometer]", file=source, key=key)
            data = inputs.odometer
            if c.rate is not None:  # decimate to the configured rate
                step = max(int(round(1.0 / (c.rate * np.median(np.diff(data.time))))), 1) if len(data) > 1 else 1
                data = OdometerData(data.time[::step], data.speed[::step], data.sigma[::step], data.signed,
                                    data.source)
            lever = cfg.vehicle_point if c.lever_arm is None else c.lever_arm
            models.append(Odometer(data, layout, cfg.vehicle_mounting, lever, c.scale))
        elif name == "zupt":
            models.append(ZeroVelocity(inputs.stillness.epochs(c.rate, *span), layout, c.sigma, c.max_speed))
        elif name == "zaru":
            z = cfg.zupt if cfg.zupt is not None else ZuptConfig()
            models.append(ZeroAngularRate(inputs.stillness.epochs(z.rate, *span), layout, c.sigma, z.max_speed))
    return models


def installation_check(imu: ImuData, static_duration: float, results: dict | None = None,
                       stillness: Stillness | None = None, configured: dict | None = None) -> dict:
    """What the data say about the installation, for a user with a new recorder.

    From the configured rest window (the first ``static_duration`` [s] of the
    installed IMU data): its roll and pitch as the mean specific force reads them
    (a car parked on a road reads within a few degrees of level; an IMU installed
    upside down or on its side reads ~180 or ~90 deg), the fraction of it the
    stillness detector calls still, and the gyro rate mean there. From the results:
    the final estimates of any installation states (``mounting`` [deg],
    ``odometer_scale``, the antenna lever-arm correction [m] and the IMU
    time-offset correction [s] with their 1-sigma) and, given the
    ``configured`` installation (``antenna_position`` (3,) [m],
    ``imu_time_offset`` [s]), the values to configure instead
    (``suggested_*``). ``warnings`` lists what looks wrong.
    """
    still_window = imu.time <= imu.start_time + static_duration
    out: dict = {"rest_window_s": float(static_duration), "warnings": []}
    if still_window.sum() < 10:
        out["warnings"].append("the configured rest window holds fewer than 10 IMU samples")
        return out
    f = imu.dvel[still_window].sum(0) / imu.dt[still_window].sum()   # mean specific force, body
    roll = float(np.degrees(np.arctan2(-f[1], -f[2])))
    pitch = float(np.degrees(np.arctan2(f[0], np.hypot(f[1], f[2]))))
    out.update(rest_roll_deg=roll, rest_pitch_deg=pitch,
               rest_gyro_rate_dps=float(np.degrees(np.linalg.norm(imu.dtheta[still_window].sum(0)
                                                                  / imu.dt[still_window].sum()))))
    if max(abs(roll), abs(pitch)) > 10.0:
        out["warnings"].append(f"the installed IMU is not level at rest (roll {roll:.1f} deg, pitch {pitch:.1f} "
                               "deg): check installation.imu_rotation / imu_misalignment")
    if stillness is not None:
        frac = float(stillness.mask[still_window].mean())
        out["rest_window_still_fraction"] = frac
        if frac < 0.5:
            out["warnings"].append(f"only {100 * frac:.0f} % of the configured rest window looks still: check "
                                   "alignment.static_duration")
    for name, res in (results or {}).items():
        est = getattr(res, "estimates", {})
        sig = getattr(res, "sigma", None)
        found = {}
        for block, key, scale, digits in (("mounting", "mounting_pitch_yaw_deg", np.degrees(1.0), 3),
                                          ("odometer_scale", "odometer_scale", 1.0, 6),
                                          ("gnss_lever", "gnss_lever_correction_m", 1.0, 4),
                                          ("imu_time_offset", "imu_time_offset_correction_s", 1.0, 5)):
            if block not in est or not len(est[block]):
                continue
            value = (scale * est[block][-1]).round(digits)
            found[key] = float(value[0]) if block in ("odometer_scale", "imu_time_offset") else value.tolist()
            if block in ("gnss_lever", "imu_time_offset") and sig is not None:
                s = (scale * sig[-1][res.layout.slice(block)]).round(digits)
                found[key.replace("_correction", "_sigma")] = float(s[0]) if len(s) == 1 else s.tolist()
        if configured and "gnss_lever_correction_m" in found and "antenna_position" in configured:
            found["suggested_antenna_position_m"] = (np.asarray(configured["antenna_position"], dtype=float)
                                                     + found["gnss_lever_correction_m"]).round(4).tolist()
        if configured and "imu_time_offset_correction_s" in found and "imu_time_offset" in configured:
            found["suggested_imu_time_offset_s"] = round(float(configured["imu_time_offset"])
                                                         + found["imu_time_offset_correction_s"], 5)
        if found:
            out.setdefault("estimated", {})[name] = found
    return out
