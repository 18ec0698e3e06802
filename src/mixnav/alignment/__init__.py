"""Initial alignment of the INS: static coarse alignment and in-motion alignment from GNSS."""

from .coarse import CoarseAlignment, coarse_align
from .motion import MotionAlignment, align_from_gnss_velocity

__all__ = ["CoarseAlignment", "coarse_align", "MotionAlignment", "align_from_gnss_velocity"]
