"""Layer 2, data: recordings from files or arrays, column roles, time units, static intervals."""
