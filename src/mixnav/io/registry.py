"""The reader registry: which function reads a file of a given kind and format.

A reader declares the kind of data it gives and the format name a dataset file uses
(``format = "..."`` of its table) and has one signature::

    @register_reader("imu", "psins")
    def read(path: Path, options: ReadOptions) -> ImuData: ...

It registers itself in its own module, and that module is all a new reader is:
:mod:`mixnav.formats` finds the registration in the source (the config checks a file's
``format`` against it without importing io) and :func:`get_reader` imports the module when a
file names its format; :func:`mixnav.io.readers.read_table` is how a pipeline reads a file. Each kind returns one data type (:data:`KIND_TYPES`), checked on return: every raw-GNSS
reader (RINEX, Android, u-blox, smartLoc) returns :class:`~mixnav.data.RawPseudoranges`, its
``corrected`` flag saying whether the broadcast corrections are still to apply; the processed
forms (:class:`~mixnav.gnss.pseudoranges.PseudorangeEpochs`,
:class:`~mixnav.gnss.observables.GnssObservations`) are what the pipelines derive from it.

Deprecated: the kind ``corrected-pseudoranges`` (smartLoc's reader, which returned
PseudorangeEpochs) is ``raw-gnss`` now; :func:`register_reader`, :func:`formats` and
:func:`get_reader` still take the old name with a DeprecationWarning (a reader registered
under it may return PseudorangeEpochs: they become corrected RawPseudoranges).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from importlib import import_module
from pathlib import Path
from typing import Any

from .. import formats as known
from ..data import GnssFixes, ImuData, OdometerData, RawPseudoranges, Trajectory, WheelOdometry
from ..errors import ConfigError

#: kind -> the one type its readers return
KIND_TYPES: dict[str, type] = {
    "imu": ImuData,
    "gnss-fixes": GnssFixes,
    "raw-gnss": RawPseudoranges,   # broadcast (corrections to apply) or corrected (smartLoc: corrected=True)
    "odometry": WheelOdometry,       # speed and yaw rate: the dead-reckoning input (odometry-gnss)
    "odometer": OdometerData,        # wheel speeds: an INS's odometer aiding ([aiding.odometer])
    "reference": Trajectory,
}

#: deprecated kind names -> the kind they are now
DEPRECATED_KINDS = {"corrected-pseudoranges": "raw-gnss"}


def _current_kind(kind: str) -> str:
    """``kind``, or the kind a deprecated name stands for now (with a DeprecationWarning)."""
    if kind in DEPRECATED_KINDS:
        import warnings
        warnings.warn(f"the reader kind '{kind}' is deprecated: use '{DEPRECATED_KINDS[kind]}' (every raw-GNSS "
                      "reader returns RawPseudoranges; corrected ones have corrected=True)", DeprecationWarning,
                      stacklevel=3)
        return DEPRECATED_KINDS[kind]
    return kind


def raw_from_epochs(epochs) -> RawPseudoranges:
    """Corrected :class:`~mixnav.data.RawPseudoranges` holding ``epochs`` (a
    :class:`~mixnav.gnss.pseudoranges.PseudorangeEpochs`: what a reader of the deprecated
    ``corrected-pseudoranges`` kind returned); ``PseudorangeEpochs.from_raw`` gives it back."""
    import numpy as np
    from ..gnss.pseudoranges import SYSTEM_LETTERS
    return RawPseudoranges(week=np.zeros(len(epochs), dtype=np.int64), tow=np.asarray(epochs.time, dtype=float),
                           epoch=np.repeat(np.arange(len(epochs), dtype=np.int64), epochs.counts()),
                           prn=epochs.sat_id, pseudorange=epochs.pseudorange, source=epochs.source or "",
                           cn0=epochs.cn0, system=np.array([SYSTEM_LETTERS[int(k)] for k in epochs.system]),
                           corrected=True, sat_ecef=epochs.sat_ecef, variance=epochs.variance,
                           elevation=epochs.elevation)


@dataclass(frozen=True)
class ReadOptions:
    """What a reader may use beyond its file: ``table``, the dataset's table of this input
    (``[imu]``, ``[gnss]``...; a reader reads the keys it knows, e.g. ``max_gap``,
    ``qualities``), and ``folder``, the data folder (companion files the table names, such as
    drive-0708's ``tag``). Without a table a reader uses its own defaults."""

    table: Any = None
    folder: Path | None = None

    def get(self, key: str, default: Any = None) -> Any:
        return default if self.table is None else getattr(self.table, key, default)

    def imu_checks(self, max_gap: float | None = None) -> dict:
        """The data checks an ``[imu]`` table sets, as the IMU readers' keywords:
        ``max_gap`` [s] (default: ``max_gap``, the format's own), ``gap_action``
        (default ``"warn"``) and ``spike_action`` (default ``"fail"``)."""
        return {"max_gap": self.get("max_gap", max_gap), "gap_action": self.get("gap_action", "warn"),
                "spike_action": self.get("spike_action", "fail")}


@dataclass(frozen=True)
class Reader:
    kind: str
    format: str
    function: Callable[[Path, ReadOptions], Any]

    def __call__(self, path: Path, options: ReadOptions | None = None):
        out = self.function(Path(path), ReadOptions() if options is None else options)
        if not isinstance(out, KIND_TYPES[self.kind]):   # a reader bug, not bad input
            raise TypeError(f"reader {self.kind}/{self.format} returned {type(out).__name__}, "
                            f"not {KIND_TYPES[self.kind].__name__}")
        return out


_READERS: dict[tuple[str, str], Reader] = {}


def register_reader(kind: str, format: str):
    """Decorator: register ``function(path, options)`` as the reader of ``kind`` files in
    ``format``; a second reader for the same pair is an error. The deprecated kind
    ``corrected-pseudoranges`` registers a ``raw-gnss`` reader (module docstring)."""
    old_kind = kind
    kind = _current_kind(kind)
    if kind not in KIND_TYPES:
        raise ValueError(f"unknown data kind '{kind}' (kinds: {', '.join(KIND_TYPES)})")

    def add(function):
        read = function
        if old_kind != kind:   # the old kind's readers returned PseudorangeEpochs
            def read(path, options):
                out = function(path, options)
                return out if isinstance(out, RawPseudoranges) else raw_from_epochs(out)
        if (kind, format) in _READERS:
            raise ValueError(f"a {kind} reader for format '{format}' is registered already")
        _READERS[(kind, format)] = Reader(kind, format, read)
        known.add(kind, format, getattr(function, "__module__", None))   # the config accepts it now
        return function
    return add


def formats(kind: str) -> tuple[str, ...]:
    """The formats of ``kind``: every built-in reader's (mixnav.formats, read from the source,
    nothing imported), then those registered at run time."""
    return known.known_formats(_current_kind(kind))   # register_reader adds every reader there


def get_reader(kind: str, format: str, key: str | None = None, file: str | None = None) -> Reader:
    """The reader of ``kind`` files in ``format`` (its module imported now, if it is a built-in
    one not imported yet); an unknown format is a ConfigError naming the config ``key`` (e.g.
    ``imu.format``) and the registered formats."""
    kind = _current_kind(kind)
    if (kind, format) not in _READERS and (kind, format) in known.builtin_readers():
        import_module(known.builtin_readers()[(kind, format)])   # it registers itself
    try:
        return _READERS[(kind, format)]
    except KeyError:
        raise ConfigError(f"unknown {kind} format '{format}' (registered: {', '.join(formats(kind)) or 'none'})",
                          file=file, key=key) from None
