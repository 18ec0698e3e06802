"""``[evaluation]``: how a dataset is scored beyond its own withheld windows (sweeps).

- ``outage_sweep``: the length of a GNSS outage withheld one window at a time across the
  whole recording after the alignment (ins-gnss datasets; :func:`mixnav.outage_sweep`);
- ``sweep_step``: the step between the windows' starts (default a third of the window);
- ``sweep_span``: ``[start, end]``, the times the windows must lie in (default: from the
  alignment to the last GNSS epoch);
- ``start_sweep``: the step between the start times of a whole causal run (datasets that
  align from their own data: odometry-gnss, gnss-raw; :func:`mixnav.start_sweep`).

The command line's ``--outage-sweep``, ``--sweep-step``, ``--sweep-span`` and
``--start-sweep`` override these keys.
"""

from __future__ import annotations

from pydantic import model_validator

from .fields import Duration, Strict, Time


class Evaluation(Strict):
    outage_sweep: Duration | None = None  # type: ignore[valid-type]
    sweep_step: Duration | None = None  # type: ignore[valid-type]
    sweep_span: tuple[Time, Time] | None = None  # type: ignore[valid-type]
    start_sweep: Duration | None = None  # type: ignore[valid-type]

    @model_validator(mode="after")
    def _span_ordered(self):
        if self.sweep_span is not None and not self.sweep_span[1] > self.sweep_span[0]:
            raise ValueError(f"sweep_span ends ({self.sweep_span[1]:g} s) before it starts "
                             f"({self.sweep_span[0]:g} s)")
        return self
