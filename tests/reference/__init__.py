"""Test-only code: numpy reference formulations of the compiled kernels, the tolerances
they are compared within, and wrappers only the tests call."""
