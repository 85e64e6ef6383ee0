"""Human-facing outputs: text and JSON reports, figures."""
