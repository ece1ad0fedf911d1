"""The tabulated BRDF on the 5 degree half/difference grid: directions and the grid, the table,
the ``.npz`` container, error metrics between two tables, and the pictures' interpolation."""
