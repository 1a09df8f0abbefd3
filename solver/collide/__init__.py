"""collide."""
