"""Independent NumPy/SciPy reference implementations that check the C++ core: imported only by
the tests and by `dualprobe bench` (the import contracts in pyproject.toml enforce it)."""
