"""What accuracy costs in time: the studies behind ``bsdfkit bench`` and docs/accuracy.md.

Each study returns a :class:`Study`: rows of (setting, error against a known truth, wall time, and for
measurements the instrument time = Σ exposures), plus the cheapest setting that reaches 1 % and 0.1 % error.
"""
from bsdfkit.bench.core import Row, Study, cheapest

__all__ = ["Row", "Study", "cheapest"]
