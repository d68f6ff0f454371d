"""Helpers shared by tests in more than one folder; conftest.py files import them, never
the other way round, and no test imports another folder's conftest.py or a test module."""
