"""Analyses built on the model: pose design, worst case, error map, drift, discovery, simulation, noise."""
