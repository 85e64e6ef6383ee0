"""Effect discovery: find where the paper's model and the data disagree, name the effect, add it.

The workflow (``discover``, imucal.analysis.discover.workflow), on interval means:

1. Fit the base model (the paper's nine parameters, plus any effects the config already lists).
   Each interval mean carries its own noise (``Intervals.mean_std``, from the interval's scatter),
   propagated to sigma_k of the residual |a_k| - g. If chi2 = sum (r_k / sigma_k)^2 is
   consistent with chi-square(dof) (upper-tail p >= ``alpha_noise``), stop: nothing to explain.
2. Show where they disagree: for each candidate effect on each axis, how much of the chi-square its
   pattern would remove (the linearised score, ``screening``).
3. Candidates (``candidates``): every effect of the grammar on every non-empty axis subset, merged
   with effects already in the model. Each is screened by a Gauss-Newton step from the current fit
   (``screening``), and the most promising ones are fitted in full (``selection``). A candidate c
   with k_c new parameters is significant when its likelihood-ratio statistic
       LR_c = (chi2_current - chi2_c) / max(1, chi2_c / dof_c)
   has a family-wise p below ``alpha_effect`` (min-p over the round's candidates,
   imucal.analysis.min_p). Among significant candidates the lowest chi2_c / scale + penalty * k_c
   wins; a non-nested competitor within ``ambiguity`` is reported as ambiguous. Pairs of terms
   are screened when two effects hide each other (the lookahead).
4. Add the winner, refit, and repeat while the residual still disagrees with the noise; then
   simplify, prune and shape-check what was found (``backward``), report axes the poses cannot
   rule out (``axes``), weigh the terms in time against a bias random walk and test the
   stochastic biases (``stochastic``).
5. The verdict (``verdict``) is a typed value decided once from what was found; its words are
   imucal.report.discover_text's.
"""
from __future__ import annotations

from imucal.analysis.discover.result import Candidate, Discovery, FoundEffect, Step
from imucal.analysis.discover.settings import DiscoverSettings
from imucal.analysis.discover.verdict import Outcome, Shortfall, Verdict, Withheld
from imucal.analysis.discover.workflow import discover

__all__ = ["Candidate", "DiscoverSettings", "Discovery", "FoundEffect", "Outcome", "Shortfall", "Step", "Verdict",
           "Withheld", "discover"]
