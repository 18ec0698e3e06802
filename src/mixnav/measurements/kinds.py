"""Observable kinds: registered names, and the integer codes the kernels use.

Every row a measurement model returns says which observable it is
(:class:`mixnav.measurements.base.Rows` ``kinds``), so a mixture filter can
give each kind its own noise mixture and a report its own NIS. Kinds are
*names* registered here; a model or a mixture that names an unknown kind is
an error, never a silent default. The codes index the kernels' per-kind
tables (``mixnav.filters._bank_kernels``); they are stable within a process
(registration order) and never written to files.

A model whose rows are used with a different noise (the undifferenced rows of
:class:`mixnav.measurements.differenced.DifferencedMeasurement`) emits the
*stationary twin* of a kind: code ``stationary(code) = code + MAX_KINDS``.

Register a new kind once, at import of the model that emits it::

    ODOMETER = register_kind("odometer")
"""

from __future__ import annotations

from types import MappingProxyType

from ..errors import ArgumentError

#: Room for this many kinds; codes of stationary twins start here.
MAX_KINDS = 32

_CODES: dict[str, int] = {}

#: Kind name -> code (a read-only live view of the registry).
KINDS = MappingProxyType(_CODES)


def register_kind(name: str) -> int:
    """Register an observable kind (idempotent) and return its code."""
    if not isinstance(name, str) or not name or not name.replace("_", "").isalnum():
        raise ArgumentError(f"a kind is a name of letters, digits and '_', got {name!r}", argument="name")
    if name in _CODES:
        return _CODES[name]
    if len(_CODES) >= MAX_KINDS:
        raise ArgumentError(f"at most {MAX_KINDS} observable kinds can be registered", argument="name")
    _CODES[name] = len(_CODES)
    return _CODES[name]


def kind_code(name: str, argument: str = "kind") -> int:
    """The code of a registered kind; an unknown name is an :class:`ArgumentError`
    listing the known ones."""
    try:
        return _CODES[name]
    except (KeyError, TypeError):
        raise ArgumentError(f"unknown observable '{name}' (known: {', '.join(_CODES)})",
                            argument=argument) from None


def kind_name(code: int) -> str:
    """The name of a code (a stationary twin reads ``'<kind>:stationary'``)."""
    base = int(code) % MAX_KINDS
    for k, c in _CODES.items():
        if c == base:
            return k + (":stationary" if code >= MAX_KINDS else "")
    raise ArgumentError(f"no observable kind has code {code}", argument="code")


#: A measurement channel (one observable of one satellite or axis, the same at every
#: epoch) has one integer id, built by :func:`channel_id` only:
#: ``kind * CHANNEL_KIND + system * CHANNEL_SYSTEM + index`` (``index`` a PRN, a
#: satellite number within its system, or an axis; ``system`` 0 where there is one).
CHANNEL_SYSTEM = 1000
CHANNEL_KIND = 1000 * CHANNEL_SYSTEM


def channel_id(kind, index, system=0):
    """The channel id of observable ``kind`` (code, int or int array), satellite or axis
    ``index`` and satellite system ``system`` (ints or int arrays, broadcast)."""
    return kind * CHANNEL_KIND + system * CHANNEL_SYSTEM + index


def channel_parts(ch: int) -> tuple[int, int, int]:
    """``(kind, system, index)`` of a channel id (the inverse of :func:`channel_id`)."""
    kind, rest = divmod(int(ch), CHANNEL_KIND)
    system, index = divmod(rest, CHANNEL_SYSTEM)
    return kind, system, index


def stationary(code):
    """The code of the stationary twin of ``code`` (int or int array)."""
    return code + MAX_KINDS


PSEUDORANGE = register_kind("pseudorange")
RANGE_RATE = register_kind("range_rate")
TDCP = register_kind("tdcp")
POSITION = register_kind("position")
VELOCITY = register_kind("velocity")
