"""Runs, metrics, figures and reports."""
