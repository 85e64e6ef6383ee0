"""Outputs for other tools: generated C, peers' calibration formats (export and import)."""
