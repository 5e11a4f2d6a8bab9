"""``motorid export --format fmu``: the identified motor as an FMI 2.0 FMU.

The FMU is generated, not hand-written: the C model function is the jaxpr of
:func:`motorid.export.motor.motor_outputs` (which calls the one model,
:mod:`motorid.model`) translated by :mod:`motorid.export.jaxpr_c`, wrapped in
the FMI 2.0 functions of :mod:`motorid.export.fmu_c` (Model Exchange without
states, and Co-Simulation).  FMPy does the parts it does: its FMI 2.0
headers, the platform binary (``fmpy.build.build_platform_binary``, CMake and
the system's C compiler), the zip archive, and the validation of the result
(``fmpy.validation.validate_fmu``: modelDescription.xml against the FMI 2.0
XML schema, variable names, model structure, units).  modelDescription.xml is
written with :mod:`xml.etree.ElementTree` from the variables table of
BENCH_LOG_FORMAT.md ("Exports") and then validated by FMPy; the C sources
travel in the FMU (``sources/``) so that an importer on another platform can
build its own binary.
"""

from __future__ import annotations

import re
import shutil
import tempfile
import uuid
import xml.etree.ElementTree as ET
from datetime import datetime, timezone
from pathlib import Path

from motorid.errors import MotorIdError
from motorid.export.fmu_c import wrapper_source
from motorid.export.jaxpr_c import emit_c_function
from motorid.export.motor import INPUTS, OUTPUTS, IdentifiedMotor, traced

#: SI base units of the variables' units (FMI 2.0 <BaseUnit> exponents)
UNITS = {
    "Pa": {"kg": "1", "m": "-1", "s": "-2"},
    "rad/s": {"s": "-1", "rad": "1"},
    "rad": {"rad": "1"},
    "K": {"K": "1"},
    "N.m": {"kg": "1", "m": "2", "s": "-2"},
    "m3/s": {"m": "3", "s": "-1"},
}


class FmuBuildError(MotorIdError):
    """The FMU could not be built or did not pass FMPy's validation."""


def model_identifier(motor: IdentifiedMotor) -> str:
    """A C identifier for the FMU: motorid_<motor name>."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", motor.spec.name).strip("_") or "motor"
    return f"motorid_{name}"


def c_source(motor: IdentifiedMotor, guid: str) -> str:
    """The whole C source of the FMU: the generated model function and the FMI 2.0 wrapper."""
    mechs = ", ".join(m.id for m in motor.mechanisms) or "none"
    header = (f"/* FMU of motor '{motor.spec.name}' identified by motorid ({motor.source}).\n"
              f"   Mechanisms included: {mechs}.\n"
              "   Generated from the jaxpr of motorid.export.motor.motor_outputs; do not edit. */\n"
              "#include <math.h>\n")
    return header + emit_c_function(traced(motor)) + wrapper_source(
        guid, [p.start for p in INPUTS], len(OUTPUTS))


def description_text(motor: IdentifiedMotor) -> str:
    spec = motor.spec
    mechs = ", ".join(m.id for m in motor.mechanisms) or "none"
    return (f"Bent-axis piston motor '{spec.name}' ({spec.pistons} pistons, {spec.displacement * 1e6:.6g} cm3/rev), "
            f"Bartos 1992 model identified by motorid; mechanisms: {mechs}. Algebraic (no states); the rotor "
            f"inertia J = {spec.inertia:.6g} kg.m2 is NOT in 'torque': put it in the load model. "
            "torque_breakaway is the static friction limit for a stick-slip (Karnopp) load model.")


def model_description(motor: IdentifiedMotor, identifier: str, guid: str, source_name: str) -> bytes:
    """modelDescription.xml (FMI 2.0, Model Exchange and Co-Simulation)."""
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": identifier, "guid": guid,
        "description": description_text(motor), "generationTool": "motorid export (FMPy for build and validation)",
        "generationDateAndTime": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "variableNamingConvention": "flat", "numberOfEventIndicators": "0"})
    for tag, extra in (("ModelExchange", {}),
                       ("CoSimulation", {"canHandleVariableCommunicationStepSize": "true"})):
        el = ET.SubElement(root, tag, {"modelIdentifier": identifier, "canNotUseMemoryManagementFunctions": "true",
                                       "canGetAndSetFMUstate": "false", "canSerializeFMUstate": "false", **extra})
        files = ET.SubElement(el, "SourceFiles")
        ET.SubElement(files, "File", {"name": source_name})
    units = ET.SubElement(root, "UnitDefinitions")
    for name, base in UNITS.items():
        ET.SubElement(ET.SubElement(units, "Unit", {"name": name}), "BaseUnit", base)
    ET.SubElement(root, "LogCategories").append(ET.Element("Category", {"name": "logStatusError"}))
    ET.SubElement(root, "DefaultExperiment", {"startTime": "0.0", "stopTime": "1.0"})
    variables = ET.SubElement(root, "ModelVariables")
    vr = 0
    for p in INPUTS:
        sv = ET.SubElement(variables, "ScalarVariable", {"name": p.name, "valueReference": str(vr),
                                                         "description": p.description, "causality": "input",
                                                         "variability": "continuous"})
        ET.SubElement(sv, "Real", {"unit": p.unit, "start": repr(float(p.start))})
        vr += 1
    for p in OUTPUTS:
        sv = ET.SubElement(variables, "ScalarVariable", {"name": p.name, "valueReference": str(vr),
                                                         "description": p.description, "causality": "output",
                                                         "variability": "continuous", "initial": "calculated"})
        ET.SubElement(sv, "Real", {"unit": p.unit})
        vr += 1
    structure = ET.SubElement(root, "ModelStructure")
    outputs = ET.SubElement(structure, "Outputs")
    initial = ET.SubElement(structure, "InitialUnknowns")
    deps = " ".join(str(k + 1) for k in range(len(INPUTS)))  # 1-based indices of the inputs
    for k in range(len(OUTPUTS)):
        index = str(len(INPUTS) + k + 1)
        ET.SubElement(outputs, "Unknown", {"index": index, "dependencies": deps})
        ET.SubElement(initial, "Unknown", {"index": index, "dependencies": deps})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def validate(path) -> list[str]:
    """FMPy's validation of an FMU file: the list of problems (empty when it passes)."""
    from fmpy.validation import validate_fmu

    return list(validate_fmu(str(path)))


def build_fmu(motor: IdentifiedMotor, out, *, quiet: bool = True) -> Path:
    """Write the FMU of ``motor`` to ``out`` (whole or not at all) and return its path.

    Raises :class:`FmuBuildError` where CMake or a C compiler is missing, the
    build fails, or FMPy's validation finds a problem.
    """
    import subprocess

    from fmpy.build import build_platform_binary
    from fmpy.util import create_zip_archive

    out = Path(out)
    if shutil.which("cmake") is None:
        raise FmuBuildError("cannot build the FMU's binary: CMake is not installed (FMPy builds with CMake)")
    identifier = model_identifier(motor)
    source_name = f"{identifier}.c"
    guid = "{" + str(uuid.uuid4()) + "}"
    with tempfile.TemporaryDirectory(prefix="motorid-fmu-") as tmp:
        unzip = Path(tmp) / "fmu"
        (unzip / "sources").mkdir(parents=True)
        (unzip / "modelDescription.xml").write_bytes(model_description(motor, identifier, guid, source_name))
        (unzip / "sources" / source_name).write_text(c_source(motor, guid))
        (unzip / "documentation").mkdir()
        (unzip / "documentation" / "index.html").write_text(
            "<html><body><h1>" + identifier + "</h1><p>" + description_text(motor) + "</p><ul>"
            + "".join(f"<li>{n}</li>" for n in motor.notes) + "</ul></body></html>\n")
        build = Path(tmp) / "build"
        build.mkdir()
        try:
            if quiet:
                _quiet_build(build_platform_binary, unzip, build)
            else:
                build_platform_binary(unzip, build, cmake_options=_CMAKE_OPTIONS)
        except FileNotFoundError as exc:
            raise FmuBuildError(f"cannot build the FMU's binary: {exc}") from None
        except subprocess.CalledProcessError as exc:
            raise FmuBuildError(f"cannot build the FMU's binary: CMake or the C compiler failed ({exc}); "
                                "is a C compiler installed?") from None
        staged = Path(tmp) / "staged.fmu"
        create_zip_archive(staged, unzip)
        problems = validate(staged)
        if problems:
            raise FmuBuildError(f"the FMU did not pass FMPy's validation: {'; '.join(problems)}")
        out.parent.mkdir(parents=True, exist_ok=True)
        partial = out.with_name(f".{out.name}.partial")
        shutil.copyfile(staged, partial)
        partial.replace(out)
    return out


#: CMake cache entries: link libm, and keep a·b + c as two roundings (no fused multiply-add)
_CMAKE_OPTIONS = {"CMAKE_C_STANDARD_LIBRARIES:STRING": "-lm", "CMAKE_C_FLAGS:STRING": "-ffp-contract=off"}


def _quiet_build(build_platform_binary, unzip, build) -> None:
    """Run FMPy's build with CMake's chatter sent to a log (shown only when it fails)."""
    import os
    import subprocess
    import sys

    log = build / "build.log"
    with open(log, "w") as fh:
        saved = os.dup(1), os.dup(2)
        try:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(fh.fileno(), 1)
            os.dup2(fh.fileno(), 2)
            build_platform_binary(unzip, build, cmake_options=dict(_CMAKE_OPTIONS))
        except subprocess.CalledProcessError as exc:
            tail = log.read_text()[-800:] if log.exists() else ""
            raise subprocess.CalledProcessError(exc.returncode, exc.cmd, output=tail) from None
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])


def require_compiler() -> str | None:
    """Why an FMU cannot be built here (None where CMake and a C compiler are found)."""
    if shutil.which("cmake") is None:
        return "CMake is not installed (FMPy builds the FMU's binary with CMake)"
    if not any(shutil.which(c) for c in ("cc", "gcc", "clang")):
        return "no C compiler (cc, gcc or clang) is on the PATH"
    return None
