"""Extended objects and groups: random-matrix tracks (paper 002)."""
