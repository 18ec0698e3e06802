"""``mixnav export``: a simulated run written as a dataset a user could have recorded.

One seeded run of a scenario with raw satellites (``[gnss.satellites]``) becomes:

- ``imu.csv``: the simulated (error-corrupted) IMU increments in the generic CSV layout
  (:mod:`mixnav.io.generic_csv`: ``time[s], dthx[rad], ..., dvz[m/s]``), time stamps in GPS
  seconds of the week of the first epoch (the first row holds the start time and zero
  increments: each row's increments are over the interval ending at its time);
- ``obs.rnx``: a RINEX 3.04 observation file of the simulated pseudoranges (``C1C``,
  satellite clocks zero), carrier phases (``L1C = carrier / lambda_L1`` [cycles], no loss of
  lock) and Doppler (``D1C = -range rate / lambda_L1``), epochs in GPS time
  (:func:`mixnav.io.rinex_write.write_rinex_obs`);
- ``nav.rnx``: a RINEX 3.04 GPS navigation file of the scenario's nominal constellation
  (:meth:`mixnav.gnss.constellation.NominalConstellation.broadcast_records`: circular orbits
  as broadcast elements with zero harmonic corrections and zero clocks), a record per
  satellite every 2 h (inside every record's fit interval); no ionosphere coefficients
  (the simulation adds no Klobuchar delay);
- several systems (``[gnss.satellites] systems``): ``obs.rnx`` is a mixed file, each
  system's first-frequency code and Doppler (:data:`mixnav.io.rinex_write.OBS_CODES`, the
  Doppler by the system's wavelength), and ``nav.rnx`` a mixed navigation file of every
  system's nominal constellation (BeiDou's records in BDT); the dataset lists the systems
  (``[raw_gnss] systems``), so ``process`` estimates an inter-system offset per further
  system. GLONASS: the simulator flies its satellites from state vectors every 30 min
  (:class:`mixnav.gnss.constellation.GlonassBroadcastOrbits`), written as GLONASS records
  (t_b in UTC, ``LEAP SECONDS`` in the header) with each slot's frequency channel, which
  the observation header's ``GLONASS SLOT / FRQ #`` lines give too;
- ``reference.csv``: the true IMU trajectory (position, velocity, attitude) at the GNSS
  epochs, on the IMU's time axis (``[reference] point = "imu"``);
- ``dataset.toml``: an ``ins-gnss`` dataset with ``[raw_gnss]`` pointing at them, the
  scenario's lever arm as ``installation.antenna_position``, its IMU model, receiver clock
  noise and observable sigmas, troposphere and ionosphere corrections off (the simulation
  has no atmosphere), an alignment (``level-then-gnss`` when the run starts at rest for at
  least 10 s, else ``gnss-velocity``), and the scenario's loose, tight and TDCP EKF methods.

The simulation time ``t`` maps to GPS time ``start + t`` (``start``: a GPS calendar time).
``mixnav process <folder>/dataset.toml`` then runs the data through the RINEX path
(:mod:`mixnav.experiment.rinex_ins`): the round trip the tests check against the
in-simulation filter.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..attitude import quat_to_euler
from ..config.scenario_schema import Scenario, StaticSegment
from ..errors import ArgumentError, ConfigError
from ..gnss.geometry import C_LIGHT, LAMBDA_L1, SECONDS_PER_WEEK
from ..io.atomic import atomic_write_text
from ..io.outdir import staged_output
from ..io.rinex_write import write_rinex_nav, write_rinex_nav_multi, write_rinex_obs
from ..sim.scenario import SimulatedRun, constellation, simulate

_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")
#: broadcast records every 2 h (the nominal upload interval; a record serves +-2 h 15 min)
RECORD_INTERVAL = 7200.0


@dataclass
class ExportResult:
    """What :func:`export_dataset` wrote: ``files`` (role -> path), the GPS time of the
    simulation's ``t = 0`` (``gps_start_s``, seconds since 1980-01-06), the methods
    copied into the dataset and those left out (with why)."""

    folder: Path
    files: dict
    gps_start_s: float
    seed: int
    methods: list = field(default_factory=list)
    skipped_methods: dict = field(default_factory=dict)
    sim: SimulatedRun | None = None


def gps_seconds(start: str) -> float:
    """GPS seconds since 1980-01-06 of a calendar time ``YYYY-MM-DDThh:mm:ss`` (GPS time)."""
    try:
        t = np.datetime64(start, "ns")
    except ValueError:
        raise ArgumentError(f"'{start}' is not a date and time (YYYY-MM-DDThh:mm:ss, GPS time)",
                            argument="start") from None
    ns = int((t - _GPS_EPOCH).astype("timedelta64[ns]").astype(np.int64))   # integer: a float keeps 0.24 us
    if ns < 0:
        raise ArgumentError(f"'{start}' is before the GPS epoch 1980-01-06", argument="start")
    if ns % 1_000_000_000:
        raise ArgumentError(f"'{start}' must be a whole second", argument="start")
    return float(ns // 1_000_000_000)


def _toml_str(text: str) -> str:
    """A TOML basic string (backslashes and quotes escaped)."""
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _q(v, unit: str) -> str:
    return f'"{v:.10g} {unit}"'


def _vec(vals, unit: str) -> str:
    return "[" + ", ".join(_q(v, unit) for v in vals) + "]"


def dataset_toml(sc: Scenario, name: str, lever, methods: list, alignment: dict, data_dir: str) -> str:
    """The dataset config of an export (module docstring); ``data_dir``: the folder's absolute
    path (a relative one is resolved from the working folder first: ``mixnav process --data``
    moves it)."""
    s = sc.gnss.satellites
    imu = sc.imu
    lines = [f"# {name}: simulated run of scenario '{sc.scenario.name}' exported by 'mixnav export'",
             "# (IMU CSV + RINEX 3 observation/navigation files + reference), processed by 'mixnav process'.",
             "", "[dataset]", f'name = "{name}"',
             f'description = "scenario {sc.scenario.name} exported as IMU CSV + RINEX (simulated)"',
             'kind = "ins-gnss"', f"data_dir = {_toml_str(data_dir)}", "", "[imu]", 'format = "csv"', 'file = "imu.csv"',
             'spike_action = "fail"']
    if imu.grade is not None:
        lines.append(f'grade = "{imu.grade}"')
    if imu.errors:
        lines.append("[imu.errors]")
        for k, v in imu.errors.items():
            lines.append(f"{k} = " + ("[" + ", ".join(f'"{x}"' for x in v) + "]" if isinstance(v, list) else f'"{v}"'))
    lines += ["", "[raw_gnss]", 'format = "rinex-obs"', 'file = "obs.rnx"', 'navigation = "nav.rnx"',
              'imu_time = "gps-week-seconds"']
    if list(s.systems) != ["G"]:
        lines.append("systems = [" + ", ".join(f'"{x}"' for x in s.systems) + "]")
    lines += [
              f"elevation_mask = {_q(np.degrees(s.mask), 'deg')}",
              "troposphere = false      # the simulation adds no atmosphere",
              "ionosphere = false",
              f"pseudorange_sigma = {_q(s.pseudorange_sigma, 'm')}",
              f"range_rate_sigma = {_q(s.range_rate_sigma, 'm/s')}",
              f"carrier_sigma = {_q(s.carrier_sigma, 'm')}",
              f"clock_q_bias = {s.clock_bias_noise ** 2:.10g}",
              f"clock_q_drift = {s.clock_drift_noise ** 2:.10g}",
              "", "[reference]", 'format = "csv"', 'file = "reference.csv"', 'point = "imu"',
              "", "[installation]", f"antenna_position = {_vec(lever, 'm')}",
              "", "[alignment]", f'method = "{alignment["method"]}"',
              f"min_speed = {_q(alignment['min_speed'], 'm/s')}"]
    if alignment["method"] == "level-then-gnss":
        lines.append(f"static_duration = {_q(alignment['static_duration'], 's')}")
    lines += ['attitude_sigma = ["1 deg", "1 deg", "3 deg"]',
              'velocity_sigma = ["0.2 m/s", "0.2 m/s", "0.2 m/s"]',
              'position_sigma = ["3 m", "3 m", "5 m"]']
    for m in methods:
        lines += ["", "[[methods]]", f'name = "{m.name}"', f'type = "{m.type}"', f"states = {m.states}",
                  f'estimator = "{m.estimator}"', f"covariance_interval = {_q(m.covariance_interval, 's')}"]
        if m.type == "tight-ekf":
            lines.append(f"use_range_rate = {'true' if m.use_range_rate else 'false'}")
        if m.type == "tdcp-ekf":
            lines.append(f'tdcp_previous = "{m.tdcp_previous}"')
    return "\n".join(lines) + "\n"


def _alignment(sc: Scenario) -> dict:
    first = sc.trajectory.segments[0]
    if isinstance(first, StaticSegment) and first.duration >= 10.0 and sc.trajectory.speed == 0.0:
        return {"method": "level-then-gnss", "static_duration": float(min(first.duration - 2.0, 30.0)),
                "min_speed": 2.0}
    return {"method": "gnss-velocity", "min_speed": 2.0}


def _plain(m) -> str | None:
    """Why a method cannot be copied into the exported dataset (None: it can)."""
    if m.type not in ("loose-ekf", "tight-ekf", "tdcp-ekf"):
        return f"type '{m.type}' (the export copies loose-ekf, tight-ekf and tdcp-ekf)"
    extra = [k for k in ("robust", "mixture", "imm", "aiding", "imu_grade", "imu_errors", "options")
             if getattr(m, k, None)]
    if extra or m.smooth:
        return f"has {', '.join(extra + (['smooth'] if m.smooth else []))} (the export copies plain methods)"
    return None


def export_dataset(sc: Scenario, out_dir, seed: int | None = None, start: str = "2024-03-13T10:00:00",
                   name: str | None = None, source: str | None = None, overwrite: bool = False) -> ExportResult:
    """Simulate one run of ``sc`` and write it as an IMU + RINEX dataset (module docstring).

    Parameters
    ----------
    sc : Scenario
        With ``[gnss.satellites]``.
    out_dir : path
        The folder (the output-folder policy of :mod:`mixnav.io.outdir`: command ``export``).
    seed : int or None
        The run's seed (default: the scenario's).
    start : str
        GPS calendar time of the simulation's ``t = 0``, whole seconds.
    name : str or None
        The dataset's name (default ``<scenario>-rinex``).

    Raises
    ------
    ConfigError
        A scenario without raw satellites (``gnss.satellites``), or with a constellation
        record over PRN 32.
    """
    if sc.gnss.satellites is None:
        raise ConfigError("exporting RINEX needs raw satellites: the scenario has no [gnss.satellites]",
                          file=source, key="gnss.satellites")
    seed = sc.scenario.seed if seed is None else int(seed)
    t_gps0 = gps_seconds(start)
    systems = list(sc.gnss.satellites.systems)
    const = constellation(sc.gnss.satellites.constellation, systems)
    gps = const if systems == ["G"] else const.part("G") if "G" in systems else None
    if gps is not None and gps.prn.max() > 32:
        raise ConfigError("RINEX GPS PRNs stop at 32", file=source, key="gnss.satellites.constellation")
    sim = simulate(sc, seed, source)
    obs = sim.observations
    imu = sim.imu
    week0 = np.floor((t_gps0 + float(obs.time[0])) / SECONDS_PER_WEEK)
    base = week0 * SECONDS_PER_WEEK
    tow0 = t_gps0 - base           # GPS seconds of week0 of the simulation's t = 0 (may pass 604800)
    name = name or f"{sc.scenario.name}-rinex"
    methods, skipped = [], {}
    for m in sc.methods:
        why = _plain(m)
        if why is None:
            methods.append(m)
        else:
            skipped[m.name] = why
    if not methods:
        raise ConfigError(f"no method to copy: {skipped}", file=source, key="methods")
    lever = np.asarray(sc.gnss.lever_arm, float)
    files = {}
    with staged_output(out_dir, "export", overwrite, protect=[source] if source else (),
                       complete_file="dataset.toml") as folder:
        # IMU: a first row at the start time with zero increments, then one row per sample
        t_imu = np.concatenate([[imu.start_time], imu.time]) + tow0
        inc = np.vstack([np.zeros((1, 6)), np.hstack([imu.dtheta, imu.dvel])])
        rows = [f"{t:.9f}," + ",".join(f"{x:.17g}" for x in r) for t, r in zip(t_imu, inc)]
        atomic_write_text(folder / "imu.csv", "time[s],dthx[rad],dthy[rad],dthz[rad],dvx[m/s],dvy[m/s],dvz[m/s]\n"
                          + "\n".join(rows) + "\n")
        files["imu"] = "imu.csv"
        # RINEX observations: the valid slots of each epoch
        e, s = np.nonzero(obs.valid)
        t_abs = t_gps0 + obs.time
        wk = np.floor(t_abs / SECONDS_PER_WEEK)
        tow = (t_gps0 - wk * SECONDS_PER_WEEK) + obs.time      # week difference first (float precision)
        from ..geodesy.frames import lla_to_ecef
        multi = obs.system is not None
        if multi:   # each slot's system letter and first-frequency wavelength (the SPP's frequencies)
            from ..gnss.pseudoranges import SYSTEM_LETTERS
            from ..gnss.spp import first_frequency
            letters = np.array([SYSTEM_LETTERS[int(c)] for c in obs.system[e, s]])
            chan = const.glonass_channels if "R" in systems else {}
            wavelength = C_LIGHT / first_frequency(letters, [chan.get(int(p), 99) if x == "R" else 99
                                                             for x, p in zip(letters, obs.prn[e, s])])
        write_rinex_obs(folder / "obs.rnx", wk.astype(int), tow, e, obs.prn[e, s], obs.pseudorange[e, s],
                        doppler=-obs.range_rate[e, s] / (wavelength if multi else LAMBDA_L1),
                        carrier=obs.carrier[e, s] / (wavelength if multi else LAMBDA_L1),
                        approx_position=lla_to_ecef(sim.truth.lla[0]),
                        marker=sc.scenario.name.upper()[:20], interval=float(np.median(np.diff(obs.time))),
                        system=letters if multi else None,
                        glonass_channels=const.glonass_channels if "R" in systems else None)
        files["observations"] = "obs.rnx"
        # navigation: records every RECORD_INTERVAL covering the run (toe on whole multiples)
        t_first, t_last = t_gps0 + float(obs.time[0]), t_gps0 + float(obs.time[-1])
        toe = np.arange(np.floor(t_first / RECORD_INTERVAL), np.ceil(t_last / RECORD_INTERVAL) + 1) * RECORD_INTERVAL
        if systems == ["G"]:
            write_rinex_nav(folder / "nav.rnx", const.broadcast_records(t_gps0, toe))
        else:
            glo, leap = None, None
            if "R" in systems:   # the state vectors the simulator's GLONASS satellites flew from
                from ..gnss.gnss_time import leap_seconds
                orbits = const.part("R")
                k0 = np.floor(float(obs.time[0]) / orbits.interval) - 1
                k1 = np.ceil(float(obs.time[-1]) / orbits.interval) + 1
                glo = orbits.records(np.arange(k0, k1 + 1) * orbits.interval)
                glo["t_gps"] = t_gps0 + glo.pop("tb")
                glo["channel"] = np.array([const.glonass_channels[int(p)] for p in glo["prn"]], float)
                leap = int(leap_seconds(np.array([t_gps0 - 18.0]))[0])
            write_rinex_nav_multi(folder / "nav.rnx", {x: const.part(x).broadcast_records(t_gps0, toe, time_system=x)
                                                       for x in systems if x != "R"}, glonass=glo,
                                  leap_seconds=leap)
        files["navigation"] = "nav.rnx"
        # reference: the truth (IMU point) at the GNSS epochs
        tr = sim.truth
        k = np.searchsorted(tr.time, obs.time - 1e-9)
        rpy = np.degrees(quat_to_euler(tr.q_nb[k]))
        ref = np.column_stack([tr.time[k] + tow0, np.degrees(tr.lla[k, 0]), np.degrees(tr.lla[k, 1]), tr.lla[k, 2],
                               tr.v_n[k], rpy])
        atomic_write_text(folder / "reference.csv",
                          "time[s],lat[deg],lon[deg],height[m],vn[m/s],ve[m/s],vd[m/s],roll[deg],pitch[deg],yaw[deg]\n"
                          + "\n".join(f"{r[0]:.9f}," + ",".join(f"{x:.12f}" for x in r[1:]) for r in ref) + "\n")
        files["reference"] = "reference.csv"
        atomic_write_text(folder / "dataset.toml", dataset_toml(sc, name, lever, methods, _alignment(sc),
                                                                str(Path(out_dir).resolve())))
        files["dataset"] = "dataset.toml"
    folder_path = Path(out_dir)
    return ExportResult(folder_path, {k: folder_path / v for k, v in files.items()}, t_gps0, seed,
                        [m.name for m in methods], skipped, sim)
