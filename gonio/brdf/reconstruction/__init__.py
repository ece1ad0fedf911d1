"""From sparse rotation-stage samples to a full BRDF: the linear basis, the solver, and the
samples (simulation and file)."""
