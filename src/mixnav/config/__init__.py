"""Scenario and dataset files: the strict schemas, the loader, and the shipped configs."""

from .loader import list_datasets, list_scenarios, load_dataset, load_scenario

__all__ = ["list_datasets", "list_scenarios", "load_dataset", "load_scenario"]
