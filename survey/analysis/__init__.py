"""Reads a survey archive's Dataset, never computes an orbit: each cell's regime from the
evidence stored, where the regime changes along a family. Imports only the catalog."""
