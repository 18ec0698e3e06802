"""The version of mixnav, in a module of its own: the package root imports every
layer's public names lazily, so a layer that needs the version imports it from here
(importing the root from below would be an upward arrow)."""

__version__ = "0.1.0"
