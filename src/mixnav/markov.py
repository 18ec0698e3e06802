"""Markov transition matrices: the check shared by the IMM (:mod:`mixnav.filters.imm`) and
the config that describes one (``[methods.imm]``, :mod:`mixnav.config.method_schema`).

It sits below both so a config file's matrix is refused, with the filter's own message,
when the file is loaded, without the config importing the filter.
"""

from __future__ import annotations

import numpy as np

from .errors import ArgumentError


def check_transition(transition, r: int | None = None, argument: str = "transition") -> np.ndarray:
    """The transition matrix as an (r, r) array, or ArgumentError naming ``argument``: square,
    finite, non-negative, rows summing to one (to 1e-9)."""
    P = np.asarray(transition, dtype=float)
    if P.ndim != 2 or P.shape[0] != P.shape[1] or (r is not None and P.shape[0] != r):
        want = f"({r}, {r})" if r is not None else "square"
        raise ArgumentError(f"must be a {want} matrix, got shape {P.shape}", argument=argument)
    if not np.all(np.isfinite(P)):
        raise ArgumentError("has entries that are not finite", argument=argument)
    if np.any(P < 0):
        i, j = np.argwhere(P < 0)[0]
        raise ArgumentError(f"entry [{i}][{j}] is negative ({P[i, j]:g}): probabilities are >= 0", argument=argument)
    s = P.sum(axis=1)
    bad = np.nonzero(np.abs(s - 1.0) > 1e-9)[0]
    if bad.size:
        raise ArgumentError(f"row {bad[0]} sums to {s[bad[0]]:.6g}, not 1 (row i: the probabilities of "
                            f"going from mode i to each mode)", argument=argument)
    return P
