"""selfalign patterns."""
