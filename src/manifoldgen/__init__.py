"""manifoldgen: constrained motion planning with learned samplers."""
