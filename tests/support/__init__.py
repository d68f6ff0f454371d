"""Helpers the tests import: hypothesis strategies, the browser driver."""
