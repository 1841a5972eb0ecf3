"""Independent NumPy/SciPy reference implementations, used to check the C++ core."""
