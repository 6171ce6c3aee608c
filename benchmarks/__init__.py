"""Benchmark commands: each prints its figures, side by side with the implementations it is
compared against, in one run on the same inputs."""
