"""Scenario files: the strict schema, the loader, and the shipped scenarios."""

from .loader import list_scenarios, load_scenario

__all__ = ["list_scenarios", "load_scenario"]
