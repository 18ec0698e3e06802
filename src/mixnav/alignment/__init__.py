"""Initial alignment of the INS (coarse static alignment)."""

from .coarse import CoarseAlignment, coarse_align

__all__ = ["CoarseAlignment", "coarse_align"]
