"""One IPOPT option set and one reading of its status, for every calibration NLP.

The unknowns are in units of each parameter's predicted standard error (imucal.solve.fit), so the
tolerance means "a hundred-millionth of a standard error" (tol) or "a millionth" (acceptable) for
every parameter of every model. Three consecutive acceptable iterates end the solve: near the
optimum of a large sum of squares the objective's rounding noise (about 1e-16 of f) exceeds the
decrease a 1e-8 step predicts, and IPOPT's line search then backtracks 15-35 times per iteration
without moving (measured on the Xsens recording: 350 objective evaluations in 18 iterations with 25
required acceptable iterates, 83 in 9 with 3; the parameters differ by 5e-9 standard errors).
"""
from __future__ import annotations
from imucal.errors import raise_if_signalled

#: IPOPT options shared by the means, samples and effects fits. A trial point whose objective is not finite
#: (a step too far for the model) is IPOPT's to cut back, its outcome the solve's status: CasADi's own print
#: of it (show_eval_warnings) would reach stderr as warning text.
OPTIONS = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "show_eval_warnings": False,
           "ipopt.tol": 1e-8, "ipopt.acceptable_tol": 1e-6, "ipopt.acceptable_iter": 3,
           "ipopt.max_iter": 300}

#: The least-squares NLPs (imucal.solve.least_squares) start a few standard errors from their optimum
#: at most (initial guess, or the last optimum when the weights are refreshed), in unknowns scaled to
#: standard errors, with the angle bounds usually thousands of standard errors away: the barrier starts
#: near zero. IPOPT's default mu_init 0.1 walks away from such a start and back while mu decreases.
#: Measured on the real recordings of configs/ (means, uniform and samples fits): 2-5 iterations per
#: solve instead of 7-17, the same optima to 4e-7 standard errors (tests/test_fit_paths.py).
LEAST_SQUARES = OPTIONS | {"ipopt.mu_init": 1e-10}

#: IPOPT's return_status in words an engineer reads right.
STATUS_WORDS = {
    "Solve_Succeeded": "converged (optimal to 1e-8 of a standard error)",
    "Solved_To_Acceptable_Level": "converged (IPOPT stopped at its acceptable level, 1e-6 of a "
                                  "standard error: far below the uncertainty, the result is usable)",
    "Search_Direction_Becomes_Too_Small": "converged (the step fell below machine precision at the optimum)",
    "Maximum_Iterations_Exceeded": "did not converge: maximum iterations exceeded",
    "Infeasible_Problem_Detected": "failed: infeasible problem",
    "Restoration_Failed": "failed: restoration phase failed",
}
CONVERGED = ("Solve_Succeeded", "Solved_To_Acceptable_Level", "Search_Direction_Becomes_Too_Small")


def run(solver, **args) -> tuple[dict, dict]:
    """Call an IPOPT ``nlpsol`` and return (solution, stats).

    A signal that arrived while IPOPT ran was swallowed by CasADi as a failed evaluation; it is
    raised here again (imucal.errors.raise_if_signalled), so an interrupted run never reports a
    solver failure.
    """

    sol = solver(**args)
    raise_if_signalled()
    return sol, solver.stats()
