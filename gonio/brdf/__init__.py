"""Numerical core: pure functions over NumPy arrays. Imports nothing else from gonio."""
