"""motorid: identify bent-axis hydraulic piston motor parameters from bench logs.

The model is Bartos 1992 (JPL TDA Progress Report 42-111).  SI units inside.
"""

from motorid import _jaxconfig  # noqa: F401  (float64 + compile cache, first)

__version__ = "0.1.0"
