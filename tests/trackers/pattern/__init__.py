"""Tests of trackers.pattern."""
