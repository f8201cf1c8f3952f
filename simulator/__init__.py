"""selfalign simulator."""
