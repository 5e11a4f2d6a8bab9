"""Classical loss models of hydrostatic pumps and motors, as comparators of motorid's
model on steady operating-point tables (one module per model, each citing its source)."""

from motorid.comparators.jeong import Jeong
from motorid.comparators.mccandlish_dorey import McCandlishDorey
from motorid.comparators.polynomial import Polynomial
from motorid.comparators.schloesser import Schloesser
from motorid.comparators.wilson import Wilson


def all_comparators():
    """A fresh instance of every comparator, in order of the literature."""
    return [Wilson(), Schloesser(), McCandlishDorey(), Jeong(), Polynomial()]


__all__ = ["Jeong", "McCandlishDorey", "Polynomial", "Schloesser", "Wilson", "all_comparators"]
