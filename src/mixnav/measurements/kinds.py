"""Which observable each row of a measurement is.

Mixture filters give every kind of observable its own noise mixture; a
measurement model says the kind of each row of its ``z`` with
``row_kinds(epoch, m) -> ndarray of int (m,)``.
"""

from __future__ import annotations

PSEUDORANGE = 0
RANGE_RATE = 1
TDCP = 2
POSITION = 3
VELOCITY = 4

#: Kind name (as in scenario files) -> code.
KINDS = {"pseudorange": PSEUDORANGE, "range_rate": RANGE_RATE, "tdcp": TDCP,
         "position": POSITION, "velocity": VELOCITY}
