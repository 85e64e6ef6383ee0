"""Run settings from YAML and the bounds on every user-given count."""
