"""The interface of a catalog mechanism, for mechanisms that live under motorid/physics/.

The same contract as :class:`motorid.discrepancy.catalog.CatalogMechanism`
(hooks of :class:`motorid.discrepancy.base.Mechanism`, plus ``signature``,
``neutral()``, ``describe()``), without importing the catalog, which imports
these modules to register them (one line each in its ``_ALL``).
"""

from __future__ import annotations

from motorid.discrepancy.base import Mechanism


class CatalogEntry(Mechanism):
    """A catalog mechanism: hooks, a residual signature and words for its fit."""

    signature: str = ""  # where its residual shows in the bench data

    def neutral(self) -> dict:
        """Parameter values at which this mechanism adds exactly nothing."""
        return {k: 0.0 for k in self.parameters}

    def value(self, values: dict, name: str) -> float:
        """Parameter ``name`` from ``values`` keyed ``"<id>.<name>"`` or ``"<name>"``."""
        full = f"{self.id}.{name}"
        return float(values[full] if full in values else values[name])

    def describe(self, values: dict, spec=None) -> str:
        """One sentence on the fitted mechanism, numbers in engineering units."""
        raise NotImplementedError

    def param(self, params: dict, name: str):
        """This mechanism's parameter ``name`` from a model parameter dict."""
        return params[f"{self.id}.{name}"]

    def __reduce__(self):  # unpickle to the catalog's singleton
        from motorid.discrepancy.catalog import get

        return (get, (self.id,))
