"""Point-pattern matching and shape modes of bending extended targets (paper 000, section 4)."""
