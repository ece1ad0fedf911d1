"""BRDF models: analytic lobes, the non-parametric factored fit and the principled-parameter fit."""
