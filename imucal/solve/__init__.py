"""Layer 3, solve: the initial guess, observability checks and the one least-squares IPOPT path."""
