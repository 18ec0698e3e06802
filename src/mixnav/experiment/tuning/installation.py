"""The installation mixnav estimates as states, written back into the file when the criterion agrees.

The tuned method is run once on the span with the antenna lever-arm correction
(``estimate = ["gnss_lever"]``) and, when it has NHC or odometer aiding, the vehicle mounting
(``"mounting"``: pitch and yaw) as extra states; the final causal estimate (every fix up to
the span's end used) and its sigma are the proposal. The proposal is written into a copy of
the file (``installation.antenna_position`` plus the correction; ``aiding.vehicle_mounting``
plus the pitch and yaw) and kept only when the cross-validation criterion improves, so an
estimate that is not significant, or that the data cannot use, leaves the file as it was.
"""

from __future__ import annotations

import numpy as np
import tomlkit

from ... import units as u
from .parameters import Parameter, get_value, set_value

ANTENNA = Parameter("installation.antenna_position", ("installation", "antenna_position"), u.LENGTH, "m", "shift",
                    (), (), -100.0, 100.0, default=(0.0, 0.0, 0.0), about="antenna position in the body frame")
MOUNTING = Parameter("aiding.vehicle_mounting", ("aiding", "vehicle_mounting"), u.ANGLE, "deg", "shift", (), (),
                     -np.pi, np.pi, default=(0.0, 0.0, 0.0), about="roll, pitch, yaw of the IMU body in the vehicle")


def proposal(evaluator, doc_text: str):
    """``(document with the estimates written in, {key: (value text, how)})`` or None when the
    method cannot estimate them (not a loose EKF, or no estimate came out)."""
    ds = evaluator.dataset(doc_text)
    if not ds.methods or getattr(ds.methods[0], "type", None) != "loose-ekf":
        return None
    m = ds.methods[0]
    want = ["gnss_lever"] + (["mounting"] if {"nhc", "odometer"} & set(m.aiding or ()) else [])
    ds = ds.model_copy(update={"methods": [m.model_copy(update={"estimate": sorted(set(m.estimate or ()) | set(want))})]})
    po = evaluator.run(ds, [])
    res = po.results.get(m.name)
    if res is None or "gnss_lever" not in res.estimates or not len(res.estimates["gnss_lever"]):
        return None
    doc = tomlkit.parse(doc_text)
    notes = {}
    dl = res.estimates["gnss_lever"][-1]
    sl = res.sigma[-1][res.layout.slice("gnss_lever")]
    ant = get_value(doc, ANTENNA) + dl
    set_value(doc, ANTENNA, ant)
    notes[ANTENNA.name] = (f"[{', '.join(f'{x:.3f}' for x in ant)}] m",
                           "estimated as a state (gnss_lever) over the span, final causal estimate; correction "
                           f"[{', '.join(f'{x:+.3f}' for x in dl)}] +- [{', '.join(f'{x:.3f}' for x in sl)}] m")
    if "mounting" in res.estimates and len(res.estimates["mounting"]) and "aiding" in doc:
        dm = res.estimates["mounting"][-1]                # pitch, yaw [rad]
        sm = res.sigma[-1][res.layout.slice("mounting")]
        mount = get_value(doc, MOUNTING)
        mount[1:3] += dm
        set_value(doc, MOUNTING, mount)
        notes[MOUNTING.name] = (f"[{', '.join(f'{np.degrees(x):.3f}' for x in mount)}] deg",
                                "estimated as states (mounting pitch, yaw) over the span, final causal estimate; "
                                f"correction [{np.degrees(dm[0]):+.3f}, {np.degrees(dm[1]):+.3f}] +- "
                                f"[{np.degrees(sm[0]):.3f}, {np.degrees(sm[1]):.3f}] deg")
    return doc, notes
