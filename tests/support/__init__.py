"""Helpers shared by tests in more than one folder (never imported from a conftest.py)."""
