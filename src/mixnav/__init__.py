"""mixnav: GNSS/INS integrated navigation when the noise is not Gaussian."""

__version__ = "0.1.0"
