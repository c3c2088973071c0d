"""Reliability tests: faults, loads and bad input against the real services."""
