"""Cycle slips in recorded carrier phases: where a satellite's carrier stops being one
continuous arc (so a time difference of it, TDCP, would carry a jump of whole or half cycles).

Per satellite (one signal each), an observation ``b`` and the satellite's previous
observation ``a`` with a carrier (times ``t_a < t_b``, ``dt = t_b - t_a``), the carrier at
``b`` does NOT continue the arc of ``a`` when any of these holds (reasons, counted):

- ``loss of lock``: the RINEX loss-of-lock indicator of the carrier at ``b`` has bit 0 set
  (the receiver says lock was lost since the previous observation: a slip is possible).
- ``half-cycle change``: bit 1 (half-cycle ambiguity) differs between ``a`` and ``b``. A
  half-cycle ambiguity that stays set is a constant offset of the arc (it cancels in a time
  difference); a receiver that resolves it (the bit clears) or loses it (the bit sets) moves
  the carrier by half a cycle at that epoch: treated as a slip.
- ``gap``: ``dt > max_gap * interval`` (default 1.5 intervals; ``interval`` the median epoch
  spacing): epochs without this satellite's carrier in between, lock not continuous.
- ``Doppler``: the carrier change disagrees with the Doppler integrated over ``dt`` by the
  trapezoid rule. RINEX carrier and Doppler have opposite signs (the carrier grows with the
  range, the Doppler is positive for an approaching satellite), so without a slip::

      r = (phi_b - phi_a) + (D_a + D_b) / 2 * dt      ~ 0      [cycles]

  and ``|r| > n_sigma * sigma_r`` is a slip. Its sigma from the noise of the two Doppler
  values and the two carriers, ``sigma_r^2 = dt^2 sigma_D^2 / 2 + 2 sigma_phi^2``, plus the
  trapezoid rule's error, which is zero for a constant line-of-sight acceleration and
  grows with its change (a vehicle). ``doppler_sigma = None`` (default) measures ``sigma_r``
  instead on the data, per system: 1.4826 x the median absolute deviation of ``r`` over
  the consecutive pairs with no loss of lock (robust to the slips themselves as long as
  they are fewer than half the pairs), which takes in the receiver's real Doppler noise,
  the multipath and the dynamics; a pair ``dt`` away from the interval scales it by
  ``dt / interval``. ``n_sigma = 5``: a two-sided Gaussian tail of 5.7e-7 per test, i.e.
  less than one false alarm expected in a million pairs of clean data; a slip of one cycle
  is seen when ``sigma_r < 0.2`` cycles (u-blox F9P at 1 Hz on urbannav: 0.11-0.13).
  Pairs without both Doppler values are not tested by it (counted ``no Doppler check``).
  The receiver clock enters the carrier as its phase and the Doppler as its frequency: its
  phase noise beyond the integrated frequency (a clock random walk; a clock step) is the
  same at every satellite of the epoch, so ``common_mode`` (default) takes off each
  residual the median of the epoch's other residuals (3 or more pairs); one satellite's
  slip does not move a median of several. Leaving the satellite itself out keeps its
  residual independent of the median (with it, the median pins one or two residuals of
  every epoch near zero and the measured sigma comes out low); the median of ``n - 1``
  Gaussian residuals has variance about ``pi sigma_r^2 / (2 (n - 1))``, by which a given
  ``doppler_sigma``'s ``sigma_r`` is widened (the measured one contains it).
- ``geometry-free``: with a second frequency, the geometry-free combination
  ``gf = lambda_1 phi_1 - lambda_2 phi_2`` [m] keeps only the ionosphere (times
  ``1 - f_1^2 / f_2^2``), the ambiguities and noise; a jump
  ``|gf_b - gf_a| > n_sigma * 2 sigma_gf + gf_rate * dt`` is a slip on either frequency
  (``2 sigma_gf``: four carriers of sigma ``sigma_gf`` [m] each, 3 mm default, a u-blox
  carrier at good C/N0; ``gf_rate`` 1 cm/s the ionosphere's change allowed, well above a
  quiet ionosphere's few mm/s). Blind to slips with ``lambda_1 dn_1 = lambda_2 dn_2``
  (e.g. GPS L1/L2: 77 and 60 cycles): the Doppler check is not.

An observation that starts an arc (the satellite's first carrier, or its first after a
blank one) is counted as ``arc start``; one without a carrier as ``no carrier``. Neither
continues an arc. :attr:`CycleSlips.continuous` is what a TDCP needs: True where the carrier
at this observation and at the satellite's previous epoch belong to one arc.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import ArgumentError
from .geometry import C_LIGHT

__all__ = ["REASONS", "CycleSlips", "detect_cycle_slips", "slips_of_observations", "mark_carrier_arcs",
           "carrier_frequency", "carrier_wavelength", "observation_wavelengths", "carrier_of_rows",
           "static_tdcp_residuals"]

#: reason name -> bit of :attr:`CycleSlips.flags`
REASONS: dict[str, int] = {"loss of lock": 1, "half-cycle change": 2, "gap": 4, "Doppler": 8,
                           "geometry-free": 16, "arc start": 32, "no carrier": 64}
#: reasons that end an arc a satellite was tracking (a slip proper; the other two are no arc)
SLIP_REASONS = ("loss of lock", "half-cycle change", "gap", "Doppler", "geometry-free")

#: carrier frequencies [Hz] per RINEX 3 system and band digit (RINEX 3.05 table 5; GLONASS
#: FDMA bands 1 and 2 are ``base + k step``, handled apart)
_BANDS = {
    "G": {"1": 1575.42e6, "2": 1227.60e6, "5": 1176.45e6},
    "R": {"3": 1202.025e6, "4": 1600.995e6, "6": 1248.06e6},
    "E": {"1": 1575.42e6, "5": 1176.45e6, "6": 1278.75e6, "7": 1207.14e6, "8": 1191.795e6},
    "C": {"2": 1561.098e6, "5": 1176.45e6, "6": 1268.52e6, "7": 1207.14e6, "8": 1191.795e6},
    "J": {"1": 1575.42e6, "2": 1227.60e6, "5": 1176.45e6, "6": 1278.75e6},
}
_GLONASS_FDMA = {"1": (1602.0e6, 0.5625e6), "2": (1246.0e6, 0.4375e6)}


def carrier_frequency(system, code, channel=None, version: float = 3.04) -> np.ndarray:
    """Carrier frequency [Hz] (m,) of each observation's signal.

    Parameters
    ----------
    system : array_like of str (m,)
        RINEX system letters.
    code : array_like of str (m,)
        RINEX 3 observation codes (``C1C``, ``L2L``, ...: the band is the second character).
    channel : array_like of int (m,) or None
        GLONASS frequency channels (-7..13); NaN result where missing.
    version : float
        The file's RINEX version: BeiDou band 1 is B1I (1561.098 MHz) for ``1I/1Q/1X`` before
        3.03 (3.02 wrote B1I as band 1) and for ``1I/1Q`` always; B1C (1575.42 MHz) otherwise.
    """
    sysarr = np.asarray(system).astype(str)
    codes = np.asarray(code).astype(str)
    m = len(sysarr)
    f = np.full(m, np.nan)
    k = np.full(m, np.nan) if channel is None else np.asarray(channel, float)
    for i in range(m):
        s, c = sysarr[i], codes[i]
        if len(c) < 2:
            continue
        band, attr = c[1], c[2:3]
        if s == "R" and band in _GLONASS_FDMA:
            if np.isfinite(k[i]) and -7 <= k[i] <= 13:
                base, step = _GLONASS_FDMA[band]
                f[i] = base + k[i] * step
        elif s == "C" and band == "1":
            b1i = attr in ("I", "Q") or (attr == "X" and version < 3.03)
            f[i] = 1561.098e6 if b1i else 1575.42e6
        else:
            f[i] = _BANDS.get(s, {}).get(band, np.nan)
    return f


def carrier_wavelength(system, code, channel=None, version: float = 3.04) -> np.ndarray:
    """``c / f`` [m] (m,) of :func:`carrier_frequency`."""
    return C_LIGHT / carrier_frequency(system, code, channel, version)


@dataclass(frozen=True)
class CycleSlips:
    """What :func:`detect_cycle_slips` found, per observation (m,) of its input.

    Attributes
    ----------
    continuous : ndarray of bool (m,)
        The carrier continues the arc of the satellite's previous observation
        (``previous``): a TDCP between the two is free of slips, as far as the checks see.
    flags : ndarray of uint8 (m,)
        Bits of :data:`REASONS` that hold at this observation (several may).
    previous : ndarray of int (m,)
        Index of the satellite's previous observation with a carrier; -1 where none.
    doppler_residual : ndarray (m,)
        ``r`` of the module docstring [cycles] against ``previous``; NaN where not tested.
    doppler_sigma : dict
        Per system, ``sigma_r`` at one interval [cycles] (given, or measured on the data).
    gf_jump : ndarray (m,)
        Geometry-free change against ``previous`` [m]; NaN without a second carrier.
    counts : dict
        System -> reason -> observations (a slip with two reasons counts under both), plus
        ``no Doppler check`` (pairs the Doppler check could not test).
    interval : float
        The epoch spacing the gap rule used [s].
    """

    continuous: np.ndarray
    flags: np.ndarray
    previous: np.ndarray
    doppler_residual: np.ndarray
    doppler_sigma: dict
    gf_jump: np.ndarray
    counts: dict = field(default_factory=dict)
    interval: float = float("nan")

    def slips(self) -> np.ndarray:
        """bool (m,): an arc ended at this observation (any of :data:`SLIP_REASONS`)."""
        bits = sum(REASONS[r] for r in SLIP_REASONS)
        return (self.flags & bits) != 0


def _leave_one_out_median(x: np.ndarray) -> np.ndarray:
    """``median(x without x_i)`` for every ``i`` ((n,), n >= 2), from one sort."""
    n = len(x)
    order = np.argsort(x)
    srt = x[order]
    p = np.empty(n, np.int64)
    p[order] = np.arange(n)            # rank of each element

    def rest(q):                        # element q of the sorted array without rank p
        return np.where(q < p, srt[np.minimum(q, n - 1)], srt[np.minimum(q + 1, n - 1)])
    m = n - 1
    if m % 2:
        return rest(np.full(n, m // 2))
    return 0.5 * (rest(np.full(n, m // 2 - 1)) + rest(np.full(n, m // 2)))


def _as(name, a, m, dtype=float):
    if a is None:
        return None
    a = np.asarray(a, dtype)
    if a.shape != (m,):
        raise ArgumentError(f"must have shape ({m},) like carrier, got {a.shape}", argument=name)
    return a


def detect_cycle_slips(time, epoch, satellite, carrier, *, doppler=None, lli=None, system=None,
                       carrier2=None, lli2=None, wavelength=None, wavelength2=None, interval=None,
                       max_gap: float = 1.5, doppler_sigma=None, carrier_sigma: float = 0.02,
                       n_sigma: float = 5.0, gf_sigma: float = 0.003, gf_rate: float = 0.01,
                       common_mode: bool = True) -> CycleSlips:
    """Cycle slips of every satellite's carrier (module docstring).

    Parameters
    ----------
    time : ndarray (k,)
        Epoch times [s], increasing.
    epoch : ndarray of int (m,)
        Epoch of each observation.
    satellite : array_like (m,)
        A key naming the satellite and signal of each observation (e.g. ``"G05"``, or an
        integer id); at most one observation per key and epoch.
    carrier : ndarray (m,)
        Carrier phase [cycles], NaN where blank.
    doppler : ndarray (m,) or None
        Doppler [Hz] (positive approaching, RINEX), NaN where blank; None: no Doppler check.
    lli : ndarray of int (m,) or None
        The carrier's loss-of-lock indicator (bit 0 lost lock, bit 1 half-cycle ambiguity).
    system : array_like of str (m,) or None
        System letters, for the per-system counts and the Doppler sigma; None: all ``"G"``.
    carrier2, lli2 : ndarray (m,) or None
        A second frequency's carrier [cycles] and indicator (same satellite, same epoch):
        the geometry-free check, and its loss of lock counted too.
    wavelength, wavelength2 : ndarray (m,) or None
        [m] of the two carriers (needed with ``carrier2``; :func:`carrier_wavelength`).
    interval : float or None
        Epoch spacing [s]; None: the median of ``diff(time)``.
    max_gap : float
        A pair further apart than ``max_gap * interval`` is a gap.
    doppler_sigma : float or None
        Doppler noise [Hz] per value; None: ``sigma_r`` measured on the data per system.
    carrier_sigma : float
        Carrier noise [cycles] in ``sigma_r`` when ``doppler_sigma`` is given.
    n_sigma : float
        Threshold of both tests in sigmas.
    gf_sigma : float
        Carrier noise [m] of each frequency in the geometry-free test.
    gf_rate : float
        Geometry-free change allowed per second [m/s] (the ionosphere).
    common_mode : bool
        Take each epoch's median Doppler residual (over its tested pairs, at least 3) off its
        residuals: the part every satellite shares (module docstring).
    """
    t = np.asarray(time, float)
    ep = np.asarray(epoch, np.int64)
    m = len(ep)
    phi = _as("carrier", carrier, m)
    if phi is None or phi.shape != (m,):
        raise ArgumentError(f"carrier must have shape ({m},) like epoch", argument="carrier")
    if m and (ep.min() < 0 or ep.max() >= len(t)):
        raise ArgumentError(f"epoch indices must lie in 0..{len(t) - 1}", argument="epoch")
    if len(t) > 1 and not (np.diff(t) > 0).all():
        raise ArgumentError("epoch times must increase", argument="time")
    if not (n_sigma > 0 and max_gap > 0 and carrier_sigma >= 0 and gf_sigma >= 0 and gf_rate >= 0):
        raise ArgumentError("n_sigma and max_gap must be positive, the sigmas and gf_rate not negative",
                            argument="n_sigma")
    dop = _as("doppler", doppler, m)
    lli = _as("lli", lli, m, np.int64)
    lli2 = _as("lli2", lli2, m, np.int64)
    phi2 = _as("carrier2", carrier2, m)
    lam = _as("wavelength", wavelength, m)
    lam2 = _as("wavelength2", wavelength2, m)
    if phi2 is not None and (lam is None or lam2 is None):
        raise ArgumentError("the geometry-free check needs both wavelengths", argument="wavelength2")
    sysarr = np.full(m, "G") if system is None else np.asarray(system).astype(str)
    if sysarr.shape != (m,):
        raise ArgumentError(f"must have shape ({m},)", argument="system")
    if interval is None:
        interval = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    if not interval > 0:
        raise ArgumentError("must be positive", argument="interval")
    sat = np.asarray(satellite)
    if sat.shape != (m,):
        raise ArgumentError(f"must have shape ({m},)", argument="satellite")
    _, key = np.unique(sat, return_inverse=True)
    key = key.reshape(-1)

    flags = np.zeros(m, np.uint8)
    has = np.isfinite(phi)
    flags[~has] |= REASONS["no carrier"]
    # the previous observation with a carrier of the same key: sort the carrier rows by (key, epoch)
    rows = np.nonzero(has)[0]
    order = rows[np.lexsort((ep[rows], key[rows]))]
    previous = np.full(m, -1, np.int64)
    same = key[order][1:] == key[order][:-1]
    if (same & (ep[order][1:] == ep[order][:-1])).any():
        raise ArgumentError("a satellite key appears twice in one epoch", argument="satellite")
    b, a = order[1:][same], order[:-1][same]
    previous[b] = a
    start = has & (previous < 0)
    flags[start] |= REASONS["arc start"]

    dt = t[ep[b]] - t[ep[a]]
    if lli is not None:
        flags[b[(lli[b] & 1) != 0]] |= REASONS["loss of lock"]
        flags[b[((lli[b] ^ lli[a]) & 2) != 0]] |= REASONS["half-cycle change"]
    if lli2 is not None:
        flags[b[(lli2[b] & 1) != 0]] |= REASONS["loss of lock"]
        flags[b[((lli2[b] ^ lli2[a]) & 2) != 0]] |= REASONS["half-cycle change"]
    flags[b[dt > max_gap * interval]] |= REASONS["gap"]

    resid = np.full(m, np.nan)
    sigma_of = {}
    no_check = np.zeros(m, bool)
    if dop is not None:
        r = (phi[b] - phi[a]) + 0.5 * (dop[a] + dop[b]) * dt
        tested = np.isfinite(r) & (dt <= max_gap * interval)
        inflate = np.ones(len(b))
        if common_mode:   # the receiver clock's phase noise, the same at every satellite: off
            eb = ep[b]
            for e in np.unique(eb[tested]):
                at = np.nonzero(tested & (eb == e))[0]
                if len(at) >= 3:
                    r[at] -= _leave_one_out_median(r[at])
                    inflate[at] = np.sqrt(1.0 + np.pi / (2.0 * (len(at) - 1)))
        no_check[b[~tested & (dt <= max_gap * interval)]] = True
        resid[b[tested]] = r[tested]
        quiet = tested & ((flags[b] & (REASONS["loss of lock"] | REASONS["half-cycle change"])) == 0)
        for s in np.unique(sysarr[b[tested]]):
            mine = sysarr[b] == s
            if doppler_sigma is None:
                sample = r[quiet & mine] * (interval / dt[quiet & mine])
                if len(sample) < 30:   # too few pairs of this system to measure: pool every system
                    sample = r[quiet] * (interval / dt[quiet])
                if not len(sample):
                    continue
                sig1 = 1.4826 * float(np.median(np.abs(sample - np.median(sample))))
                sig = sig1 * dt[mine] / interval
            else:
                sig1 = float(np.sqrt(interval ** 2 * doppler_sigma ** 2 / 2 + 2 * carrier_sigma ** 2))
                sig = np.sqrt(dt[mine] ** 2 * doppler_sigma ** 2 / 2 + 2 * carrier_sigma ** 2) * inflate[mine]
            sigma_of[str(s)] = sig1
            bad = tested[mine] & (np.abs(r[mine]) > n_sigma * sig)
            flags[b[mine][bad]] |= REASONS["Doppler"]
    else:   # no Doppler at all: every pair within the gap rule goes untested by it (said, not silent)
        no_check[b[dt <= max_gap * interval]] = True

    gf_jump = np.full(m, np.nan)
    if phi2 is not None:
        gf = lam * phi - lam2 * phi2
        d = gf[b] - gf[a]
        ok = np.isfinite(d)
        gf_jump[b[ok]] = d[ok]
        bad = ok & (np.abs(d) > n_sigma * 2.0 * gf_sigma + gf_rate * dt)
        flags[b[bad]] |= REASONS["geometry-free"]

    cont = has & (previous >= 0) & (flags == 0)
    counts = {}
    for s in np.unique(sysarr):
        mine = sysarr == s
        c = {name: int(((flags[mine] & bit) != 0).sum()) for name, bit in REASONS.items()}
        c["no Doppler check"] = int(no_check[mine].sum())
        c["observations"] = int(mine.sum())
        c["continuous"] = int(cont[mine].sum())
        counts[str(s)] = c
    return CycleSlips(continuous=cont, flags=flags, previous=previous, doppler_residual=resid,
                      doppler_sigma=sigma_of, gf_jump=gf_jump, counts=counts, interval=float(interval))


def observation_wavelengths(obs) -> np.ndarray:
    """[m] (m,) of each row's signal (GLONASS by its channel; NaN without one)."""
    from ..data import NO_CHANNEL
    ch = obs.glonass_channel().astype(float)
    ch[ch == NO_CHANNEL] = np.nan
    code = np.full(len(obs.prn), "C1C") if obs.signal is None else np.asarray(obs.signal).astype(str)
    return carrier_wavelength(obs.systems(), code, ch, float(obs.version or 3.04))


def slips_of_observations(obs, second=None, **options) -> CycleSlips:
    """:func:`detect_cycle_slips` on a raw-GNSS reader's observations.

    Parameters
    ----------
    obs : RawPseudoranges
        With ``carrier`` (and ``doppler``, ``lli`` when read); GLONASS rows need their
        channel only for the geometry-free check.
    second : RawPseudoranges or None
        The same file read for a second signal per system (e.g. ``signals = {"G": "C2L"}``):
        its carrier and loss-of-lock indicator are matched to ``obs``'s rows by GPS time and
        satellite (NaN where the satellite has no second carrier) for the geometry-free check.
    **options
        Passed on (``doppler_sigma``, ``n_sigma``, ``max_gap``, ...).
    """
    from ..data import LLI_COLUMNS
    if obs.carrier is None:
        raise ArgumentError(f"{obs.source} has no carrier phase of the signals read", argument="obs")
    t_ep = (np.asarray(obs.week, float) - float(obs.week[0])) * 604800.0 + np.asarray(obs.tow, float)
    sat = obs.satellite_ids()
    col = LLI_COLUMNS.index("carrier")
    kw = dict(doppler=obs.doppler, lli=None if obs.lli is None else obs.lli[:, col], system=obs.systems())
    if second is not None and second.carrier is not None:
        t2 = ((np.asarray(second.week, float) - float(obs.week[0])) * 604800.0 + np.asarray(second.tow, float))
        # one key per (time to the microsecond, satellite) in both reads
        k1 = np.char.add(np.round(t_ep[obs.epoch] * 1e6).astype(np.int64).astype(str), sat)
        k2 = np.char.add(np.round(t2[second.epoch] * 1e6).astype(np.int64).astype(str), second.satellite_ids())
        order = np.argsort(k2)
        pos = np.clip(np.searchsorted(k2[order], k1), 0, max(len(k2) - 1, 0))
        hit = (k2[order][pos] == k1) if len(k2) else np.zeros(len(k1), bool)
        j = order[pos]
        phi2 = np.where(hit, second.carrier[j], np.nan)
        lli2 = np.where(hit, 0 if second.lli is None else second.lli[j, col], 0)
        kw.update(carrier2=phi2, lli2=lli2, wavelength=observation_wavelengths(obs),
                  wavelength2=np.where(hit, observation_wavelengths(second)[j], np.nan))
    kw.update(options)
    return detect_cycle_slips(t_ep, obs.epoch, sat, obs.carrier, **kw)


def mark_carrier_arcs(obs, wavelength: float | None = None, **options):
    """The padded observables (:class:`mixnav.gnss.observables.GnssObservations`, carrier [m],
    range rate [m/s]) with ``carrier_continuous`` from :func:`detect_cycle_slips` (the range
    rate as Doppler ``-rr / lambda``), and the :class:`CycleSlips` found.

    Parameters
    ----------
    obs : GnssObservations
    wavelength : float or None
        [m] of every slot's carrier; None: GPS L1.
    **options
        Passed on (``doppler_sigma`` [Hz], ``n_sigma``, ...).
    """
    from dataclasses import replace
    from .geometry import LAMBDA_L1
    lam = LAMBDA_L1 if wavelength is None else float(wavelength)
    e, k = np.nonzero(obs.valid)
    cs = detect_cycle_slips(obs.time, e, obs.prn[e, k], obs.carrier[e, k] / lam,
                            doppler=-obs.range_rate[e, k] / lam, **options)
    cont = np.zeros(obs.valid.shape, bool)
    cont[e, k] = cs.continuous
    return replace(obs, carrier_continuous=cont), cs


def carrier_of_rows(obs, epochs, rho, epoch_of, slips: CycleSlips | None = None):
    """Each corrected pseudorange row's carrier [m] with the same corrections, and whether it
    continues its satellite's arc.

    Parameters
    ----------
    obs : RawPseudoranges
        With ``carrier`` [cycles].
    epochs : PseudorangeEpochs
        :func:`mixnav.gnss.spp.corrected_pseudoranges` of ``obs``.
    rho : ndarray (m,)
        ``obs``'s pseudoranges as corrected (clock-jump offset off) [m].
    epoch_of : ndarray of int (E,)
        The ``obs`` epoch of each of ``epochs``' epochs.
    slips : CycleSlips or None
        Of ``obs`` (default: :func:`slips_of_observations` with its defaults).

    Returns
    -------
    carrier : ndarray (M,)
        ``lambda phi + (corrected - raw pseudorange)`` [m]: the satellite clock, group delay
        and atmosphere of the row's pseudorange (constant parts cancel in a time
        difference; the ionosphere's change over an epoch enters twice, below a millimetre
        per second for the broadcast model); NaN where the observation has no carrier.
    continuous : ndarray of bool (M,)
    source : ndarray of int (M,)
        The ``obs`` row of each row.
    """
    from .pseudoranges import SYSTEM_LETTERS
    if slips is None:
        slips = slips_of_observations(obs)
    lam = observation_wavelengths(obs)
    letters = obs.systems().astype(str)
    row_of = {(int(j), s, int(p)): i for i, (j, s, p) in enumerate(zip(obs.epoch, letters, obs.prn))}
    M = len(epochs.pseudorange)
    src = np.empty(M, np.int64)
    for e in range(len(epochs)):
        sl = epochs.rows_of(e)
        j = int(epoch_of[e])
        for r in range(sl.start, sl.stop):
            src[r] = row_of[(j, SYSTEM_LETTERS[int(epochs.system[r])], int(epochs.sat_id[r]))]
    carrier = lam[src] * obs.carrier[src] + (epochs.pseudorange - np.asarray(rho, float)[src])
    return carrier, slips.continuous[src], src


def static_tdcp_residuals(epochs, carrier, point_ecef, trusted, max_gap: float = 1.5):
    """TDCP of consecutive epochs less the range change seen from a known static antenna,
    less each epoch's receiver clock change (the median over its ``trusted`` pairs): what is
    left of a carrier's time difference is its noise and multipath, plus any cycle slip it
    carries. A check of recorded carriers and of the slip flags that needs no filter.

    Parameters
    ----------
    epochs : PseudorangeEpochs
        Corrected pseudorange rows (satellites at transmit time).
    carrier : ndarray (M,)
        Carrier of each row [m] (:func:`carrier_of_rows`).
    point_ecef : ndarray (3,)
        The antenna [m].
    trusted : ndarray of bool (M,)
        Rows whose pair sets the epoch's clock change (e.g. ``continuous``); an epoch with
        fewer than 3 trusted pairs is left out.
    max_gap : float
        Epochs further apart than ``max_gap`` median intervals are not differenced.

    Returns
    -------
    rows, previous : ndarray of int (P,)
        The row at each epoch and the same satellite's row at the epoch before (every pair
        with a carrier at both).
    residual : ndarray (P,)
        [m].
    """
    from .geometry import earth_rotation_correction
    x = np.asarray(point_ecef, float)
    s = epochs.sat_ecef
    tau = np.linalg.norm(s - x, axis=1) / C_LIGHT
    geo = np.linalg.norm(earth_rotation_correction(s, tau) - x, axis=1)
    key = epochs.system.astype(np.int64) * 1000 + epochs.sat_id
    dt = np.diff(epochs.time)
    limit = max_gap * (float(np.median(dt)) if len(dt) else 1.0)
    out_r, out_p, out_d = [], [], []
    for e in range(1, len(epochs)):
        if epochs.time[e] - epochs.time[e - 1] > limit:
            continue
        a, b = epochs.rows_of(e - 1), epochs.rows_of(e)
        ra, rb = np.arange(a.start, a.stop), np.arange(b.start, b.stop)
        _, ib, ia = np.intersect1d(key[rb], key[ra], assume_unique=True, return_indices=True)
        r, p = rb[ib], ra[ia]
        d = (carrier[r] - carrier[p]) - (geo[r] - geo[p])
        ok = np.isfinite(d)
        r, p, d = r[ok], p[ok], d[ok]
        good = np.asarray(trusted)[r]
        if good.sum() < 3:
            continue
        out_r.append(r)
        out_p.append(p)
        out_d.append(d - np.median(d[good]))
    if not out_r:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    return np.concatenate(out_r), np.concatenate(out_p), np.concatenate(out_d)
