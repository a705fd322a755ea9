"""Industrial arms from their published DH parameters (filled in by the zoo work)."""
