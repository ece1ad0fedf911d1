"""From sparse rotation-stage samples to a full BRDF: the linear basis, the solver, periodic
interpolation along the rotation (``periodic``, also used by adaptive plans), and the samples
(simulation and file)."""
