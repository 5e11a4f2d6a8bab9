"""The identified motor in the simulators engineers use (issue 18).

- :mod:`motorid.export.motor`     the one function all exports translate: the model at an operating point
- :mod:`motorid.export.source`    result.json (+ spec, + diagnosis.json) → :class:`IdentifiedMotor`
- :mod:`motorid.export.jaxpr_flat`, :mod:`~motorid.export.jaxpr_c`, :mod:`~motorid.export.jaxpr_numpy`
                                  the jaxpr of that function, flattened and translated to C and NumPy
- :mod:`motorid.export.fmu`       FMI 2.0 FMU (Model Exchange + Co-Simulation), built and validated with FMPy
- :mod:`motorid.export.simscape`  tabulated losses for Simscape Fluids' Fixed-Displacement Motor (TL)
- :mod:`motorid.export.python`    a self-contained NumPy module

:func:`export` is the library entry point of ``motorid export``.
"""

from __future__ import annotations

from pathlib import Path

FORMATS = ("fmu", "simscape", "python")


#: what the Simscape tables never evaluate: static friction (the tables' friction is 0 at ω = 0, where
#: the model's stuck friction would act; they ramp through it between ±speed_min)
SIMSCAPE_UNUSED = ("KFS", "Ks")


def export(result_dir, fmt: str, out, motor=None, diagnosis: bool = True, assume=None, displacement=None,
           **options) -> Path:
    """Export the motor identified in ``result_dir`` as ``fmt`` to ``out``; returns the path written.

    fmt : "fmu" (a .fmu file), "simscape" (a folder), "python" (a .py file);
    motor : spec TOML where result.json's cannot be found; diagnosis : include
    the accepted mechanisms of a diagnosis.json beside result.json; assume : {parameter: value
    [SI]} for parameters the fit did not determine (:func:`~motorid.export.source.load_identified`);
    displacement : [m³/rev] the setting of a variable unit to export at (None: the spec's);
    options : of :func:`motorid.export.simscape.loss_tables` (simscape only).
    """
    from motorid.errors import InputError
    from motorid.export.source import load_identified

    if fmt not in FORMATS:
        raise InputError(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    unused = SIMSCAPE_UNUSED if fmt == "simscape" else ()
    identified = load_identified(result_dir, motor=motor, diagnosis=diagnosis, assume=assume, unused=unused,
                                 displacement=displacement,
                                 why_unused="static friction does not enter the loss tables (their friction "
                                            "is 0 at zero speed): taken as 0, which changes no value")
    if fmt == "fmu":
        from motorid.export.fmu import FmuBuildError, build_fmu

        try:
            return build_fmu(identified, out)
        except FmuBuildError as exc:
            raise InputError(str(exc)) from None
    if fmt == "simscape":
        from motorid.export.simscape import write_simscape

        return write_simscape(identified, out, **options)
    from motorid.export.python import write_python

    return write_python(identified, out)
