"""motorid: identify bent-axis hydraulic piston motor parameters from bench logs.

The model is Bartos 1992 (JPL TDA Progress Report 42-111).  SI units inside.

The Python API (:mod:`motorid.api`), loaded on first use so that ``import motorid``
imports neither JAX nor pandas:

- :func:`read_logs`       bench logs → one SI ``pandas.DataFrame``
- :func:`fit`             logs + motor spec → :class:`FitResult` (print, ``.plot()``, ``.to_json()``)
- :func:`diagnose`        logs + motor spec → :class:`DiagnosisResult` (the missing physics, named)
- :func:`predict`         a fit + operating points → torque, flows, efficiencies with 95 % bands
- :func:`load_result`     a saved result.json → :class:`FitResult`
- :class:`MotorSpec`, :func:`load_motor_spec`   the known motor data
"""

import os as _os

# float64 from JAX's first import on (motorid._jaxconfig, imported by every module that computes, sets it too)
_os.environ.setdefault("JAX_ENABLE_X64", "1")

from motorid._version import __version__  # noqa: E402,F401

#: the names of the top-level API, each an attribute of motorid.api
_API = ("read_logs", "fit", "diagnose", "predict", "load_result", "load_motor_spec", "MotorSpec", "OilSpec", "FitResult",
        "DiagnosisResult")
__all__ = list(_API)


def __getattr__(name):
    if name in _API:
        from motorid import api

        return getattr(api, name)
    raise AttributeError(f"module 'motorid' has no attribute '{name}'")


def __dir__():
    return sorted(list(globals()) + list(_API))
