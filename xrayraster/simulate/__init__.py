"""Scene + scan geometry + physics -> projections: GL path lengths composed with the physics."""
