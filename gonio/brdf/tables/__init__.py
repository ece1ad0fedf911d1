"""The tabulated BRDF on the 5 degree half/difference grid: directions and the grid, the table,
the ``.npz`` container, and error metrics between two tables."""
