"""Formation tracks by template matching (paper 003)."""
