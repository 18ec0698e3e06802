"""Readers of data files and atomic writers of results."""
