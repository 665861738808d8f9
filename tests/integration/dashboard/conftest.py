"""Shared helpers for the dashboard tests (the ``port_offset`` fixture is the suite's,
in tests/conftest.py: an offset claimed against every other test process)."""
