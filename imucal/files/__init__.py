"""Safe file access: bounded reading of untrusted inputs, safe YAML, atomic collision-checked outputs."""
