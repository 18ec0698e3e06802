"""Initial alignment of the INS: static coarse alignment, in-motion alignment from GNSS, and
levelling at rest followed by the heading from GNSS once moving."""

from .coarse import CoarseAlignment, coarse_align
from .level_gnss import LevelGnssAlignment, align_level_then_gnss
from .in_motion import MotionAlignment, align_from_gnss_velocity

__all__ = ["CoarseAlignment", "coarse_align", "MotionAlignment", "align_from_gnss_velocity",
           "LevelGnssAlignment", "align_level_then_gnss"]
