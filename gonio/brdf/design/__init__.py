"""Where to put the light/sensor pairs: rig feasibility, the condition-number design search,
industrial presets, the roughness bound and the held-out error estimate."""
