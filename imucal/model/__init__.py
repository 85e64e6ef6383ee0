"""Layer 1, maths: the paper's sensor model, effects and parameters, written once in CasADi."""
