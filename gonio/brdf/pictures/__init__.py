"""Pictures of a BRDF: rendered sphere/swatch images and the half/difference slice preview."""
