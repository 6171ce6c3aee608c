"""Clients of the tracking service: publishers, replay, followers and scenario simulation."""
