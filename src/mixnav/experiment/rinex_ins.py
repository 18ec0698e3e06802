"""``mixnav process`` for an ``ins-gnss`` dataset whose GNSS is a RINEX observation file
(``[raw_gnss]``): the tightly coupled INS on pseudoranges and Doppler.

Steps:

1. Read the IMU (any IMU format, the installation applied as for fixes), the RINEX
   observation file (the raw-GNSS reader of ``raw_gnss.format``, :func:`mixnav.io.rinex_obs.read_rinex_obs`: GPS C1C and D1C when
   present; every system of ``raw_gnss.systems``, each its first-frequency signal), the
   navigation file (:class:`mixnav.gnss.ephemeris.BroadcastEphemeris`; with systems beyond
   GPS every navigation file as one :class:`~mixnav.gnss.multi_ephemeris.MultiEphemeris`,
   GLONASS channels from its records) and the reference.
2. One time axis: RINEX epochs are GPS time; the IMU time stamps are GPS seconds of the
   week of the first RINEX epoch or GPS seconds since 1980 (``raw_gnss.imu_time``), after
   ``installation.imu_time_offset``. Times inside the run are seconds since the first IMU
   sample (as every INS dataset); the reference's time stamps are read on the IMU's axis.
   A RINEX file with no epoch inside the IMU's span is a DataError naming both files.
3. SPP of every epoch (:func:`mixnav.gnss.spp.solve_epochs`); receiver clock jumps seen
   by it come off the pseudoranges (:func:`mixnav.gnss.spp.clock_jumps`). The SPP fixes,
   with the receiver velocity from the Doppler (:func:`mixnav.gnss.raw_observations.doppler_velocity`)
   when the file has it, are what the alignment (``[alignment]``, as for recorded fixes)
   and the loosely coupled methods use.
4. The pseudoranges with the broadcast corrections (the one correction function,
   :func:`mixnav.gnss.spp.corrected_pseudoranges`: satellite clock with the relativistic
   term and T_GD, Saastamoinen troposphere, Klobuchar ionosphere when the navigation header
   has its coefficients, else warned and reported as ``ionosphere: skipped``), evaluated at
   the latest SPP fix (the first before it), and the Doppler range rates (satellite clock
   drift removed) become the tight filter's observables
   (:func:`mixnav.gnss.raw_observations.tight_observations`, the Earth's rotation during the
   travel time applied): :class:`mixnav.measurements.tight.TightGnss` applies the antenna
   lever arm to the range and to the range rate (its Jacobians cover attitude, and the
   gyro bias through ``w x l``).
   With a ``tdcp-ekf`` method the carrier (``L1C``) of each slot comes too, in metres
   with its pseudorange's corrections, and whether it continues its satellite's arc
   (:func:`carrier_observations`, :mod:`mixnav.gnss.cycle_slips`: TDCP rows only there);
   with ``[raw_gnss] second_signals`` the files are read once more for those signals, and
   their carrier adds the geometry-free check (:func:`read_second_signals`).
5. The tight methods start from the alignment with the receiver clock bias and drift of
   the SPP / Doppler solution at the alignment time (17-state layout, ``states = 17``).
   Several systems: the filter's clock is that of the first of G R E C J present, and its
   layout gets one inter-system offset state per further system
   (:func:`mixnav.measurements.tight.tight_layout`), started at the SPP's offsets
   (:func:`clock_start`).
   Outputs, metrics and report as every INS dataset (:func:`mixnav.experiment.pipelines.ins_fixes.write`).
"""

from __future__ import annotations

import time as _time
import warnings
from collections import Counter
from dataclasses import dataclass, replace

import numpy as np

from ..config.dataset_schema import Dataset
from ..data import LLI_COLUMNS, GnssFixes, RawPseudoranges
from ..errors import ConfigError, DataError
from ..geodesy.frames import dcm_ecef_to_ned, ecef_to_lla
from ..gnss.ephemeris import BroadcastEphemeris
from ..gnss.geometry import SECONDS_PER_WEEK
from ..gnss.raw_observations import doppler_velocity, tight_observations
from ..gnss.spp import clock_jumps, corrected_pseudoranges, solve_epochs
from ..ins.error_model import ClockModel
from ..io.imu_checks import DataWarning
from ..io.readers import ReadOptions, get_reader
from ..sim.gnss import in_windows
from .aiding import AidingInputs, installation_check
from .spp_process import _iono_alpha, _systems_of, check_first_frequency, gps_rows, options as spp_options
from .spp_process import read_navigation as read_navigation_multi


def _subset(obs, keep):
    """The epochs ``keep`` (bool (m,)) of GnssObservations."""
    f = {k: getattr(obs, k) for k in ("time", "valid", "prn", "sat_pos", "sat_vel", "pseudorange", "range_rate",
                                      "carrier", "elevation", "clock", "pr_variance", "system",
                                      "carrier_continuous")
         if getattr(obs, k) is not None}
    return replace(obs, **{k: v[keep] for k, v in f.items()})


def read_observations(paths, read=None, options: ReadOptions | None = None) -> RawPseudoranges:
    """The pseudoranges (and Doppler, carrier, C/N0 when read) of one or more RINEX observation
    files or u-blox logs, in time order (:func:`mixnav.io.rinex_obs.read_rinex_obs` or
    :func:`mixnav.io.ubx.read_ubx` each): one record whose
    epochs run on from file to file. A file that does not start after the previous one's
    last epoch is a DataError naming it; Doppler missing from some of the files is NaN
    there (counted as ``no Doppler`` by the tight observables), as are carrier and C/N0.
    ``read``: the raw-GNSS reader (default: the registered ``rinex-obs`` one); ``options``:
    its options (the ``[raw_gnss]`` table: ``systems``, ``signals``)."""
    read = get_reader("raw-gnss", "rinex-obs") if read is None else read
    parts = [read(p, options) for p in paths]
    if len(parts) == 1:
        return parts[0]
    for prev, (p, cur) in zip(parts, zip(paths[1:], parts[1:])):
        last = prev.week[-1] * SECONDS_PER_WEEK - cur.week[0] * SECONDS_PER_WEEK + prev.tow[-1]
        if not cur.tow[0] > last:
            raise DataError(f"its first epoch (GPS week {cur.week[0]}, {cur.tow[0]:.3f} s) is not after the last "
                            f"epoch of {prev.source}: give the observation files in time order, without overlap",
                            file=str(p))
    offsets = np.cumsum([0] + [len(x.tow) for x in parts[:-1]])
    cat = np.concatenate

    def optional(name, blank):
        """An optional per-measurement field over the files (``blank`` where a file has none)."""
        if all(getattr(x, name) is None for x in parts):
            return None
        return cat([np.full(len(x.prn), blank) if getattr(x, name) is None else getattr(x, name) for x in parts])

    glonass = {}
    for x in parts:   # the headers' GLONASS channels (a slot given twice differently: DataError)
        glonass = x.with_glonass_channels(glonass).glonass_channels
    rejected = sum((Counter(x.rejected) for x in parts), Counter())
    events = sum((Counter(x.event_records) for x in parts), Counter())
    return RawPseudoranges(
        week=cat([x.week for x in parts]), tow=cat([x.tow for x in parts]),
        epoch=cat([x.epoch + o for x, o in zip(parts, offsets)]), prn=cat([x.prn for x in parts]),
        pseudorange=cat([x.pseudorange for x in parts]), code="/".join(dict.fromkeys(x.code for x in parts)),
        rejected=dict(rejected), epochs_all_rejected=sum(x.epochs_all_rejected for x in parts),
        version=parts[0].version, source=", ".join(x.source for x in parts), event_records=dict(sorted(events.items())),
        doppler=optional("doppler", np.nan), cn0=optional("cn0", np.nan), carrier=optional("carrier", np.nan),
        system=optional("system", "G"), signal=optional("signal", ""),
        lli=cat([np.zeros((len(x.prn), len(LLI_COLUMNS)), np.int8) if x.lli is None else x.lli for x in parts])
        if any(x.lli is not None for x in parts) else None,
        glonass_channels=glonass,
        leap_seconds=None if all(x.leap_seconds is None for x in parts) else
        cat([np.full(len(x.tow), np.nan) if x.leap_seconds is None else x.leap_seconds for x in parts]))


def read_navigation(paths) -> BroadcastEphemeris:
    """The GPS broadcast records of one or more RINEX navigation files, as one ephemeris (the
    Klobuchar coefficients of the first header that has them)."""
    parts = [BroadcastEphemeris.from_rinex(p) for p in paths]
    if len(parts) == 1:
        return parts[0]
    rec = {k: np.concatenate([x.rec[k] for x in parts]) for k in parts[0].rec}
    iono = next((x for x in parts if x.iono_alpha is not None), None)
    return BroadcastEphemeris(rec, source=", ".join(x.source for x in parts),
                              iono_alpha=None if iono is None else iono.iono_alpha,
                              iono_beta=None if iono is None else iono.iono_beta)


def epoch_axis(ds: Dataset, obs) -> tuple[np.ndarray, float]:
    """Seconds of each RINEX epoch on the IMU file's own time axis ((k,)), and the offset
    added to the IMU file's times to make them GPS seconds since 1980 ([s])."""
    if ds.raw_gnss.imu_time == "gps-week-seconds":
        base = float(obs.week[0]) * SECONDS_PER_WEEK
    else:
        base = 0.0
    # the week difference first: GPS seconds since 1980 as one float keep only 0.24 us
    t = (np.asarray(obs.week, float) * SECONDS_PER_WEEK - base) + np.asarray(obs.tow, float)
    return t, base


@dataclass
class RinexInputs:
    """The files of an ins-gnss dataset with ``[raw_gnss]``, read (step 1 of the module docstring)."""

    imu: object               # ImuData, installation applied, the file's own times
    obs: RawPseudoranges
    eph: BroadcastEphemeris   # or a MultiEphemeris (systems beyond GPS)
    obs_files: list
    nav_files: list
    reference: object         # Trajectory or None
    read_time_s: float
    second: RawPseudoranges | None = None   # the second signals (tdcp-ekf's geometry-free check)


def process_rinex_ins(ds: Dataset, source: str, folder):
    """Read, align and filter an ``ins-gnss`` dataset with ``[raw_gnss]`` (module docstring).
    Returns a :class:`mixnav.experiment.ins_common.ProcessOutput`."""
    return run_rinex_ins(ds, source, folder, read_rinex_ins(ds, source, folder))


def read_rinex_ins(ds: Dataset, source: str, folder) -> RinexInputs:
    """Step 1: the IMU (installation applied), the observation and navigation files, the
    reference; a tight method asking for range rates of a file without Doppler is refused here."""
    from .ins_common import install, read_imu, read_reference
    c = ds.raw_gnss
    t_read = _time.perf_counter()
    imu = install(read_imu(ds, folder), ds)
    obs_files = [folder / f for f in c.files("file")]
    nav_files = [folder / f for f in c.files("navigation")]
    multi = several_systems(c)
    if multi:
        check_first_frequency(c, source)
    obs = read_observations(obs_files, get_reader("raw-gnss", c.format, key="raw_gnss.format", file=source),
                            ReadOptions(c, folder))
    if multi:   # every navigation file as one MultiEphemeris; a listed system without records is warned about
        eph = read_navigation_multi(c, folder, source)
        if "R" in c.systems and "R" in eph:
            obs = obs.with_glonass_channels(eph["R"].channels())
    else:
        eph = read_navigation(nav_files)
    for i, m in enumerate(ds.methods):   # before any work
        if m.type == "tight-ekf" and m.use_range_rate and obs.doppler is None:
            raise ConfigError(f"method '{m.name}' uses range rates, but {obs.source} has no Doppler (D1C/D1) column: "
                              "set use_range_rate = false", file=source, key=f"methods[{i}].use_range_rate")
        if m.type == "tdcp-ekf" and obs.carrier is None:
            raise ConfigError(f"method '{m.name}' is TDCP, but {obs.source} has no carrier phase (L1C/L1) of the "
                              "signals read: use type = \"tight-ekf\"", file=source, key=f"methods[{i}].type")
    second = None
    if c.second_signals and any(m.type == "tdcp-ekf" for m in ds.methods):
        second = read_second_signals(c, obs_files, folder, obs, source)
    reference = read_reference(ds, folder)
    return RinexInputs(imu, obs, eph, obs_files, nav_files, reference, _time.perf_counter() - t_read, second)


def read_second_signals(c, obs_files, folder, obs: RawPseudoranges, source) -> RawPseudoranges:
    """The observation files read again for ``[raw_gnss] second_signals``: the systems named
    there, each its named signal (codes in order of preference, as ``signals``), with the
    GLONASS channels of the first read. Its carrier (and loss-of-lock indicator) is what the
    geometry-free cycle-slip check sets against the first signal's. A file without a carrier
    of those signals is a ConfigError naming the key."""
    table = c.model_copy(update={"systems": [s for s in c.systems if s in c.second_signals],
                                 "signals": dict(c.second_signals)})
    second = read_observations(obs_files, get_reader("raw-gnss", c.format, key="raw_gnss.format", file=source),
                               ReadOptions(table, folder))
    if second.carrier is None or not np.isfinite(second.carrier).any():
        raise ConfigError(f"{obs.source} has no carrier phase of the second signals "
                          f"({second.code}) for the geometry-free check", file=source, key="raw_gnss.second_signals")
    return second.with_glonass_channels(obs.glonass_channels) if obs.glonass_channels else second


def several_systems(c) -> bool:
    """Whether a ``[raw_gnss]`` table names systems beyond GPS (then every navigation file is
    read as one :class:`~mixnav.gnss.multi_ephemeris.MultiEphemeris`; GPS alone keeps the GPS
    records of :func:`read_navigation`, its results bit for bit)."""
    return tuple(c.systems) != ("G",)


def run_rinex_ins(ds: Dataset, source: str, folder, inputs: RinexInputs):
    """Steps 2-5 on the files read (module docstring); a ProcessOutput."""
    from .ins_common import ProcessOutput, _shift, data_checks, initial_state, run_ins_methods
    c = ds.raw_gnss
    imu, obs, eph, reference, read_time = inputs.imu, inputs.obs, inputs.eph, inputs.reference, inputs.read_time_s
    obs_files, nav_files = inputs.obs_files, inputs.nav_files
    obs_file = obs_files[0]     # the file an error names (the message lists them all)
    multi = hasattr(eph, "states_of")
    if not multi:
        gps_rows(obs)
    system, chan = _systems_of(obs, eph)
    if c.ionosphere and _iono_alpha(eph) is None:   # asked for, and impossible: said, not silent
        warnings.warn(f"{', '.join(map(str, nav_files))}: the header has no ionosphere (Klobuchar) coefficients, "
                      "so the ionosphere "
                      "correction is skipped and every pseudorange keeps its delay (metrics.json: "
                      "rinex.ionosphere)", DataWarning, stacklevel=3)
    t_epoch, base = epoch_axis(ds, obs)
    t0 = imu.start_time
    t_rel = t_epoch - t0
    span = float(imu.time[-1] - t0)
    inside = (t_rel >= 0.0) & (t_rel <= span)
    if not inside.any():
        raise DataError(f"the RINEX epochs (GPS {t_epoch[0] + base:.3f}..{t_epoch[-1] + base:.3f} s since 1980) and "
                        f"the IMU samples ({t0 + base:.3f}..{imu.time[-1] + base:.3f} s, raw_gnss.imu_time = "
                        f"'{c.imu_time}') do not overlap: {obs.source} and {folder / ds.imu.file} are on different time "
                        "axes (IMU times in GPS seconds of week, since 1980, or since power-on? "
                        "installation.imu_time_offset?)", file=str(obs_file))
    imu = _shift(imu, t0)
    if reference is not None:
        reference = _shift(reference, t0)

    opts = spp_options(ds)
    t_spp = _time.perf_counter()
    track = solve_epochs(eph, obs.week, obs.tow, obs.epoch, obs.prn, obs.pseudorange, opts, system=system,
                         glonass_channel=chan)
    offset, jumps, spikes = clock_jumps(t_rel, track.clock_bias, track.ok, float(c.clock_jump))
    ok = track.ok
    if not ok.any():
        raise DataError(f"no RINEX epoch could be solved by SPP (status counts: {track.status_counts()}; "
                        f"satellites skipped: {track.skipped_satellites})", file=str(obs_file))
    # the corrections at the latest fix (the first fix before it): metres off move them by millimetres
    k = np.arange(len(t_rel))
    last = np.maximum.accumulate(np.where(ok, k, -1))
    last = np.where(last >= 0, last, int(np.nonzero(ok)[0][0]))
    rx = track.pos_ecef[last]
    rho = np.asarray(obs.pseudorange, float) - offset[np.asarray(obs.epoch, int)]
    epochs, skipped = corrected_pseudoranges(eph, obs.week, obs.tow, obs.epoch, obs.prn, rho, rx, opts,
                                             source=obs.source, doppler=obs.doppler, system=system,
                                             glonass_channel=chan)
    # epochs.time counts from the first RINEX epoch; rows of epoch e came from RINEX epoch j
    j_of = np.searchsorted(t_rel - t_rel[0], epochs.time - 1e-6)
    tight, skipped_rows = tight_observations(epochs, rx[j_of], c.pseudorange_sigma, c.range_rate_sigma,
                                             opts.elevation_mask, weights=c.pseudorange_weights)
    tight = replace(tight, time=t_rel[j_of])   # the epochs' own times on the run's axis
    slips = None
    if any(m.type == "tdcp-ekf" for m in ds.methods):
        tight, slips = carrier_observations(obs, epochs, tight, j_of, rho, float(c.carrier_sigma), inputs.second)
    # receiver velocity and clock drift of each RINEX epoch from its Doppler (NaN without)
    vel_e = np.full((len(t_rel), 3), np.nan)
    drift = np.full(len(t_rel), np.nan)
    vcov = np.full((len(t_rel), 4, 4), np.nan)
    if obs.doppler is not None:
        vel_e[j_of], drift[j_of], vcov[j_of] = doppler_velocity(tight, rx[j_of])
    # onto the IMU span, without the withheld windows
    withhold = tuple(tuple(w) for w in c.withhold)
    keep = (tight.time > 0.0) & (tight.time <= span) & ~in_windows(tight.time, withhold)
    tight = _subset(tight, keep)
    fixes_all, no_velocity = spp_fixes(track, t_rel, vel_e, vcov, obs.doppler is not None, obs.source)
    fixes_in = (fixes_all.time > 0.0) & (fixes_all.time <= span)
    all_fixes = _select(fixes_all, fixes_in)
    fixes = _select(all_fixes, ~in_windows(all_fixes.time, withhold))
    solve_time = _time.perf_counter() - t_spp

    checks = data_checks(ds, source, imu, all_fixes)
    inst = ds.installation
    lever = np.asarray(inst.antenna_position, float) - np.asarray(inst.imu_position, float)
    init = initial_state(ds, imu, fixes, lever)
    letters = tight_system_letters(tight)
    init = replace(init, **clock_start(init.time, track, t_rel, offset, drift, vcov, letters))
    clock = ClockModel(float(c.clock_q_bias), float(c.clock_q_drift))
    results, aiding, filter_time = run_ins_methods(
        ds, imu, fixes, init, reference, lever, source,
        lambda: AidingInputs(ds.aiding, imu, fixes, init.time, float(imu.time[-1]), odometer=None, source=source),
        observations=tight, clock=clock)
    merged = dict(skipped)
    for key, n in skipped_rows.items():
        merged[key] = merged.get(key, 0) + n
    checks["rinex"] = {
        "observation_files": [str(f) for f in obs_files], "navigation_files": [str(f) for f in nav_files],
        "epochs": int(len(obs.tow)),
        "epochs_in_imu_span": int(inside.sum()), "doppler": obs.doppler is not None,
        "ionosphere": ("klobuchar" if _iono_alpha(eph) is not None else "skipped") if c.ionosphere else "off",
        "troposphere": bool(c.troposphere),
        "spp_status": track.status_counts(), "spp_time_s": solve_time,
        "satellites_skipped_by_spp": track.skipped_satellites,
        "observations_rejected": dict(obs.rejected), "epochs_without_gps": int(obs.epochs_all_rejected),
        "event_records_skipped": dict(obs.event_records),
        "observations_not_filtered": merged, "tight_epochs": int(len(tight)),
        "fixes_without_velocity": int(no_velocity),
        "clock_jumps": [list(j) for j in jumps], "clock_spikes_ignored": int(spikes),
        "clock0": [float(v) for v in init.clock0]}
    if multi:
        checks["rinex"].update({
            "systems": list(letters), "satellites_skipped_by_system": dict(getattr(track, "skipped_by_system", {})),
            "system_offsets0_m": {s: float(v) for s, v in zip(letters[1:], init.aux0["system_offset"])}
            if init.aux0 else {}})
    if slips is not None:
        checks["rinex"]["cycle_slips"] = slips.counts
        checks["rinex"]["doppler_slip_sigma_cycles"] = slips.doppler_sigma
        checks["rinex"]["second_signals"] = None if inputs.second is None else inputs.second.code
    return ProcessOutput(ds, source, folder, t0, imu, fixes, all_fixes, reference, lever, results, init,
                         read_time + solve_time, filter_time, aiding.summary(),
                         installation_check(imu, ds.alignment.static_duration, results, aiding.stillness,
                                            configured={"antenna_position": inst.antenna_position,
                                                        "imu_time_offset": inst.imu_time_offset}),
                         checks=checks, observations=tight)


def carrier_observations(obs: RawPseudoranges, epochs, tight, j_of, rho, sigma_cp: float, second=None):
    """The tight observables with the RINEX carrier as TDCP needs it, and the cycle slips.

    Each slot's carrier [m] is ``lambda phi`` (its signal's wavelength, GLONASS by channel)
    with the clock-jump offset and the broadcast corrections of its pseudorange applied
    (:func:`mixnav.gnss.cycle_slips.carrier_of_rows`: constant parts cancel in a time
    difference; the ionosphere enters with the code's sign where the carrier's is
    opposite, an error of twice its change over an epoch, below a millimetre per second
    for the Klobuchar model). ``carrier_continuous``: the observation's carrier continues
    its satellite's previous one (:func:`mixnav.gnss.cycle_slips.slips_of_observations`:
    loss of lock, gaps, Doppler; with ``second`` the geometry-free check too).

    Parameters
    ----------
    obs : RawPseudoranges
        The RINEX observations (``carrier`` [cycles]).
    epochs : PseudorangeEpochs
        ``corrected_pseudoranges`` of ``obs``; epoch ``e`` from RINEX epoch ``j_of[e]``.
    tight : GnssObservations
        ``tight_observations`` of ``epochs`` (slots: a subset of the epoch's rows).
    rho : ndarray (m,)
        ``obs``'s pseudoranges with the clock-jump offset taken off [m] (what was corrected).
    sigma_cp : float
        Carrier 1-sigma the filter is told [m].
    second : RawPseudoranges or None
        The same files read for a second signal per system (:func:`read_second_signals`).

    Returns
    -------
    tight : GnssObservations
        With ``carrier`` (NaN where the observation has none), ``carrier_continuous``, ``sigma_cp``.
    slips : CycleSlips
    """
    from ..gnss.cycle_slips import carrier_of_rows, slips_of_observations
    if obs.carrier is None:
        raise DataError("TDCP needs carrier phases, and the file has none of the signals read (L1C/L1 ...)",
                        file=obs.source)
    slips = slips_of_observations(obs, second)
    row_carrier, row_cont, _ = carrier_of_rows(obs, epochs, rho, j_of, slips)
    E, K = tight.valid.shape
    carrier = np.full((E, K), np.nan)
    cont = np.zeros((E, K), bool)
    for e in range(E):
        sl = epochs.rows_of(e)
        ids, prs = epochs.sat_id[sl], epochs.pseudorange[sl]
        for k in np.nonzero(tight.valid[e])[0]:
            # the slot's row: its satellite with its (copied, so bit-equal) pseudorange
            r = sl.start + np.nonzero((ids == tight.prn[e, k]) & (prs == tight.pseudorange[e, k]))[0][0]
            carrier[e, k], cont[e, k] = row_carrier[r], row_cont[r]
    return replace(tight, carrier=carrier, carrier_continuous=cont, sigma_cp=float(sigma_cp)), slips


def _select(f: GnssFixes, keep) -> GnssFixes:
    sel = lambda a: None if a is None else a[keep]  # noqa: E731
    return GnssFixes(time=f.time[keep], lla=f.lla[keep], pos_sigma=f.pos_sigma[keep], vel_n=sel(f.vel_n),
                     vel_sigma=sel(f.vel_sigma), source=f.source)


def spp_fixes(track, t_rel, vel_e, vcov, doppler: bool, source) -> tuple[GnssFixes, int]:
    """The SPP fixes (antenna) on the run's time axis, NED sigmas from the WLS covariance; with
    Doppler, the least-squares velocity of the same epoch (fixes without one are dropped and
    counted: an in-motion alignment needs every fix's velocity)."""
    ok = np.nonzero(track.ok)[0]
    lla = np.array([ecef_to_lla(p) for p in track.pos_ecef[ok]])
    C = np.array([dcm_ecef_to_ned(a[0], a[1]) for a in lla])
    cov_n = np.einsum("kij,kjl,kml->kim", C, track.cov[ok, :3, :3], C)
    pos_sigma = np.sqrt(np.einsum("kii->ki", cov_n))
    if not doppler:
        return GnssFixes(time=t_rel[ok], lla=lla, pos_sigma=pos_sigma, source=source), 0
    vel_n = np.einsum("kij,kj->ki", C, vel_e[ok])
    vcov_n = np.einsum("kij,kjl,kml->kim", C, vcov[ok, :3, :3], C)
    vel_sigma = np.sqrt(np.abs(np.einsum("kii->ki", vcov_n)))
    good = np.isfinite(vel_n).all(axis=1)
    return GnssFixes(time=t_rel[ok][good], lla=lla[good], pos_sigma=pos_sigma[good], vel_n=vel_n[good],
                     vel_sigma=vel_sigma[good], source=source), int((~good).sum())


def tight_system_letters(tight) -> tuple[str, ...]:
    """The system letters of the tight observables ``tight`` (GnssObservations), the reference
    clock's first (:func:`mixnav.measurements.tight.observation_systems`)."""
    from ..gnss.pseudoranges import SYSTEM_LETTERS
    from ..measurements.tight import observation_systems
    return tuple(SYSTEM_LETTERS[g] for g in observation_systems(tight))


def clock_start(t: float, track, t_rel, offset, drift, dcov, systems=("G",)) -> dict:
    """``clock0`` and ``sigma_clock`` of the filter's start at time ``t``: the SPP clock bias
    (jumps taken off) interpolated to ``t`` with its WLS sigma (at least 1 m), and the drift of
    the Doppler solution ``drift`` (k,) [m/s] with its sigma from ``dcov`` (k, 4, 4) (at least
    1 cm/s), else the SPP clock's slope with 1 m/s.

    Several ``systems`` (letters, the filter's reference clock first; a multi-system track):
    the clock is the reference system's (the SPP's own clock plus its offset, at the epochs
    where the SPP used that system), and ``aux0`` holds each further system's offset to it
    at the solved epoch nearest ``t`` (0 where that epoch did not use it: the block's
    initial sigma then covers it)."""
    ok = track.ok
    multi = len(systems) > 1 and getattr(track, "offsets", None)
    bias_all = track.clock_bias + (track.offsets[systems[0]] if multi else 0.0)
    ok = ok & np.isfinite(bias_all)
    tb, b = t_rel[ok], (bias_all - offset)[ok]
    j = int(np.argmin(np.abs(tb - t)))
    bias = float(np.interp(t, tb, b))
    s_bias = float(np.sqrt(track.cov[ok][j, 3, 3]))
    good = np.isfinite(drift)
    if good.any():
        i = np.nonzero(good)[0]
        d = float(np.interp(t, t_rel[i], drift[i]))
        s_drift = float(np.sqrt(dcov[i[np.argmin(np.abs(t_rel[i] - t))], 3, 3]))
    else:
        d = float(np.gradient(b, tb)[j]) if len(tb) > 1 else 0.0
        s_drift = 1.0
    out = {"clock0": np.array([bias, d]), "sigma_clock": np.array([max(s_bias, 1.0), max(s_drift, 0.01)])}
    if multi:
        e = np.nonzero(ok)[0][j]
        ref = track.offsets[systems[0]][e]
        off = [track.offsets[s][e] if s in track.offsets else np.nan for s in systems[1:]]
        out["aux0"] = {"system_offset": np.array([v - ref if np.isfinite(v) else 0.0 for v in off])}
    return out
