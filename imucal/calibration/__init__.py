"""Layer 4, result: the frozen calibration (values plus its apply map) and its file format."""
