"""Discovery's thresholds: the levels of its tests and the prices that rank its candidates."""
from __future__ import annotations

from dataclasses import dataclass

from imucal.errors import ImucalError
from imucal.model.effects import EFFECTS

#: chi-square(1) upper quantiles at p = 1e-3 and 1e-2.
CHI2_1_P1E3 = 10.828
#: The price of one more coefficient when ranking candidates and pruning axes: an axis joins a
#: term (or stays in it) when it removes more than chi-square(1) at p = 0.01. Significance is the
#: family-wise test, not this; the price only chooses among significant models (a clean axis joins
#: a true term in ~1 % of cases, a true axis of a weak term is kept more often than at p = 1e-3).
CHI2_1_P1E2 = 6.635
#: Extra room [chi-square] when choosing which screened candidates to fit in full for the
#: ambiguity check (the Gauss-Newton screen matches full fits to ~0.1 on simulated data).
SCREEN_SLACK = 5.0
#: An axis a found term lacks counts as ruled out when a coefficient there as large as the term's
#: largest would be kept (removes more than ``penalty``) at least this often (``axes.unresolved``).
RESOLVED_POWER = 0.9
#: Warm-up time constants screened, as fractions of the recording's last interval time: the
#: screen is linear in the amplitudes only, so tau is profiled on this grid and the full fit
#: starts from the best one.
TAU_GRID = (0.03, 0.06, 0.12, 0.25, 0.5)


@dataclass(frozen=True)
class DiscoverSettings:
    """Thresholds of the discovery workflow (all dimensionless)."""

    candidates: tuple[str, ...] = tuple(EFFECTS)  #: effect names to try
    alpha_noise: float = 1e-3  #: chi-square test: p below this means "residual disagrees with the noise"
    alpha_effect: float = 1e-3  #: family-wise level for adding an effect (min-p over a round's candidates)
    #: family-wise level when the omnibus chi-square test passes: a round then runs only when one
    #: candidate stands out at this stricter level (the two paths together keep clean data clean)
    alpha_scan: float = 1e-4
    penalty: float = CHI2_1_P1E2  #: chi-square per added coefficient when ranking candidates and pruning axes
    ambiguity: float = 10.0  #: competitors within this (scaled chi-square) are "cannot tell apart"
    max_effects: int = 3  #: effects added at most
    full_fits: int = 4  #: candidates fitted in full per round (best by the screening score)
    lookahead: int = 3  #: when no single candidate passes, pairs starting from this many are tried
    #: scan every still interval's samples for a step inside it and cut it there (changepoint.inner_steps)
    scan_holds: bool = True

    def __post_init__(self) -> None:
        unknown = [c for c in self.candidates if c not in EFFECTS]
        if unknown:
            raise ImucalError(f"unknown effect {unknown[0]!r}", field="candidates",
                              fix=f"choose from {', '.join(EFFECTS)}")
        if not self.candidates:
            raise ImucalError("no candidate effects", field="candidates", fix=f"choose from {', '.join(EFFECTS)}")
        for name in ("alpha_noise", "alpha_effect", "alpha_scan"):
            v = getattr(self, name)
            if not 0 < v < 1:
                raise ImucalError(f"{name} {v!r} must lie in (0, 1)", field=name,
                                  fix="give a significance level between 0 and 1, e.g. 1e-3")
        if self.max_effects < 1 or self.full_fits < 1:
            raise ImucalError("max_effects and full_fits must be >= 1", field="settings",
                              fix="give max_effects and full_fits each a whole number of at least 1")
