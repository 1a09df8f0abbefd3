"""advance."""
