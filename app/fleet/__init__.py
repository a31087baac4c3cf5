"""Fleet operations: health of every vehicle (piStatus readiness) and its assignment."""
