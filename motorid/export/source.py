"""Read what an export needs from a fit's folder: result.json, its motor spec, diagnosis.json.

result.json holds the parameter values and the motor's geometry but not its
oil, which the exports need for the viscosity at T_oil; the spec comes from
the file result.json names (``inputs.motor``, tried as given, relative to the
working folder and to RESULT_DIR) or from ``--motor``, and must agree with the
geometry result.json recorded.  A ``diagnosis.json`` beside result.json (from
``motorid diagnose --out RESULT_DIR``) adds its accepted mechanisms; the base
parameters are then those of the diagnosis' final joint fit
(``parameters_after``), refitted with the mechanisms, since result.json's
values were fitted without them.

Mechanisms that describe the bench's sensors rather than the motor (a torque
transducer's zero offset) are left out of every export, with a note.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from motorid.errors import InputError
from motorid.export.motor import IdentifiedMotor
from motorid.io.spec import load_motor_spec
from motorid.model import MotorSpec



def is_sensor(mech) -> bool:
    """True for a mechanism that changes a sensor's reading rather than the motor's physics."""
    return bool(getattr(mech, "sensor", False))


def _read_json(path: Path, what: str) -> dict:
    try:
        doc = json.loads(path.read_text())
    except OSError as exc:
        raise InputError(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc.msg}, line {exc.lineno})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{path}: {what} must be a JSON object")
    return doc


#: the K_L(θ) harmonics: where the data did not determine them the fit held them at 0 (its θ-mean
#: leakage), and so does the export
HELD_AT_ZERO = ("KL_a1", "KL_b1")


class _Undetermined:
    """What an export does with a parameter the fit left without a value: the user's value
    (``--assume KEY=VALUE``), 0 for a K_L harmonic (as the fit held it) or for a parameter the
    format never evaluates (``unused``: static friction in the Simscape tables), else a refusal
    naming the parameter and the option.  Each choice is written into the export's notes."""

    def __init__(self, assume=None, unused=(), why_unused: str = ""):
        from motorid.model import parameter_info
        from motorid.physics.registry import all_mechanisms

        self.assume = {str(k): float(v) for k, v in (assume or {}).items()}
        for k, v in self.assume.items():  # a parameter the model keeps ≥ 0 (MODEL.md) is not assumed below 0
            try:
                positive = parameter_info(k, all_mechanisms()).positive
            except KeyError:  # not a parameter at all: said once the result is read
                positive = False
            if positive and v < 0:
                raise InputError(f"--assume {k}={v:g}: {k} is ≥ 0 in the model (MODEL.md)")
        self.unused, self.why_unused = set(unused), why_unused
        self.notes: list = []
        self.used_assumptions: set = set()

    def value(self, key: str, reason: str, where: str) -> float:
        if key in self.assume:
            self.used_assumptions.add(key)
            self.notes.append(f"{key} = {self.assume[key]:.6g} assumed (--assume): the fit did not determine "
                              f"it ({reason})")
            return self.assume[key]
        from motorid.identify.identifiability import KAB_HELD_FOR_KL0

        if key in HELD_AT_ZERO or KAB_HELD_FOR_KL0 in reason:  # held at 0, another carrying it (K_L0: K_AB)
            self.notes.append(f"{key} = 0, as the fit held it: {reason}")
            return 0.0
        if key in self.unused:
            self.notes.append(f"{key}: not determined ({reason}); {self.why_unused}")
            return 0.0
        raise InputError(f"{where}: parameter '{key}' has no value ({reason}); the export needs it: give it "
                         f"with --assume {key}=VALUE (e.g. from another test of the motor)")


def _value(entry, key: str, where: str, undetermined: _Undetermined | None = None) -> float:
    value = entry.get("value") if isinstance(entry, dict) else entry
    if value is None:
        reason = entry.get("reason", "not determined by the logs") if isinstance(entry, dict) else ""
        if undetermined is not None:
            return undetermined.value(key, reason, where)
        raise InputError(f"{where}: parameter '{key}' has no value ({reason}); the export needs every parameter")
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{where}: parameter '{key}' must be a number, got {value!r}") from None
    if not math.isfinite(value):
        raise InputError(f"{where}: parameter '{key}' must be finite, got {value!r}")
    return value


def _check_spec(spec: MotorSpec, motor: dict, spec_path, result_path) -> None:
    checks = (("pistons", spec.pistons, motor.get("pistons")),
              ("displacement_m3", spec.displacement, motor.get("displacement_m3")),
              ("inertia_kg_m2", spec.inertia, motor.get("inertia_kg_m2")),
              ("leak_phase_rad", spec.phase, motor.get("leak_phase_rad")))
    for key, have, want in checks:
        if want is None:
            continue
        if not math.isclose(float(have), float(want), rel_tol=1e-9, abs_tol=1e-15):
            raise InputError(f"{spec_path}: motor spec does not match {result_path} (motor.{key}: spec "
                             f"{have!r}, result {want!r})")
    if spec.oil is None:
        raise InputError(f"{spec_path}: the motor spec has no [oil] table; the export needs the oil for the "
                         "viscosity at T_oil")


def _find_spec(doc: dict, result_dir: Path, result_path: Path) -> tuple[MotorSpec, str]:
    """The motor spec of ``doc`` → (spec, where from): the first file it may name (``inputs.motor`` as
    written, relative to the working folder, to RESULT_DIR, then RESULT_DIR/motor.toml) whose geometry
    agrees with result.json's — a relative name run from another folder may find another motor's
    file, which is passed over — else the spec's TOML a table fit keeps in result.json
    (``motor_spec``); else the first disagreement, or that none was found, in one line."""
    from motorid.io.spec import parse_stored_spec

    named = (doc.get("inputs") or {}).get("motor")
    cands = []
    if isinstance(named, str) and named:
        p = Path(named)
        cands += [p] if p.is_absolute() else [Path.cwd() / p, result_dir / p, result_dir / p.name]
    cands.append(result_dir / "motor.toml")
    tried, first_error = [], None
    for cand in dict.fromkeys(cands):
        tried.append(str(cand))
        if not cand.is_file():
            continue
        try:
            spec = load_motor_spec(cand)
            _check_spec(spec, doc["motor"], cand, result_path)
        except InputError as exc:  # another motor's spec, or a stray file that is no spec: passed over
            first_error = first_error or exc
            continue
        return spec, str(cand)
    if isinstance(doc.get("motor_spec"), str) and doc["motor_spec"].strip():
        where = f"{result_path} motor_spec"
        spec = parse_stored_spec(doc["motor_spec"], where)
        _check_spec(spec, doc["motor"], where, result_path)
        return spec, where
    if first_error is not None:
        raise first_error
    raise InputError(f"{result_path}: cannot recover the motor spec (the oil is not in result.json; looked for "
                     f"{', '.join(tried)}); give it with --motor SPEC.toml")


def _setting(spec: MotorSpec, doc: dict, displacement, result_path) -> tuple[MotorSpec, list]:
    """The spec at the displacement setting exported (``displacement`` [m³/rev] or None) → (spec, notes).
    A fit of a variable unit (a table with a displacement column) is the model at each point's D: it
    exports at any setting; a fixed unit's at its own only."""
    import dataclasses

    table = doc.get("table") if isinstance(doc.get("table"), dict) else {}
    variable = bool(table.get("variable_displacement"))
    if displacement is None:
        if not variable:
            return spec, []
        return spec, [f"the fit is of a variable unit (a displacement per point); this export is at the spec's "
                      f"displacement, {spec.displacement * 1e6:.4g} cm3/rev: another setting with --displacement CM3"]
    d = float(displacement)
    if not (math.isfinite(d) and d > 0):
        raise InputError(f"--displacement must be a positive number of cm3/rev, got {d * 1e6!r}")
    if not variable:
        raise InputError(f"--displacement: {result_path} is a fit of a fixed-displacement unit (its data give no "
                         f"displacement per point): it exports at its own {spec.displacement * 1e6:.4g} cm3/rev only")
    return dataclasses.replace(spec, displacement=d), [
        f"at the displacement setting {d * 1e6:.4g} cm3/rev (--displacement; the variable unit's model at that D, "
        f"as the fit took each point's)"]


def load_identified(result_dir, motor=None, diagnosis: bool = True, assume=None, unused=(),
                    why_unused: str = "", displacement=None) -> IdentifiedMotor:
    """The identified motor of a fit's folder (see the module docstring).

    result_dir : folder holding result.json; motor : a spec TOML overriding the
    one result.json names; diagnosis : include the mechanisms of a
    diagnosis.json beside result.json; assume : {parameter: value [SI]} for parameters the
    fit did not determine (a map holds no breakaway: K_FS, K_s); unused : parameters the
    export never evaluates (taken as 0 where undetermined; ``why_unused`` says why, in the notes).
    A K_L harmonic the fit did not determine is 0, as the fit held it.  An assumed value for a
    parameter the fit did determine is refused.  displacement : [m³/rev] the setting of a variable
    unit to export at (None: the spec's).
    """
    undetermined = _Undetermined(assume, unused, why_unused)
    from motorid.physics.registry import get

    result_dir = Path(result_dir)
    result_path = result_dir / "result.json"
    if not result_dir.is_dir():
        raise InputError(f"{result_dir}: RESULT_DIR is not a folder")
    if not result_path.is_file():
        raise InputError(f"{result_dir}: RESULT_DIR holds no result.json (write one with motorid fit --out)")
    doc = _read_json(result_path, "result.json")
    for key in ("parameters", "motor"):
        if not isinstance(doc.get(key), dict):
            raise InputError(f"{result_path}: missing object '{key}'")
    if motor is not None:
        spec_path = Path(motor)
        spec = load_motor_spec(spec_path)
        _check_spec(spec, doc["motor"], spec_path, result_path)
    else:
        spec, spec_path = _find_spec(doc, result_dir, result_path)
    spec, setting_notes = _setting(spec, doc, displacement, result_path)

    params = {k: _value(e, k, str(result_path), undetermined) for k, e in doc["parameters"].items()}
    mech_ids = list((doc.get("fit") or {}).get("mechanisms") or [])
    notes = [f"parameters from {result_path}", f"motor spec and oil from {spec_path}"] + setting_notes

    diag_path = result_dir / "diagnosis.json"
    if diagnosis and diag_path.is_file():
        diag = _read_json(diag_path, "diagnosis.json")
        accepted = diag.get("mechanisms") or []
        if accepted:
            after = diag.get("parameters_after") or {}
            for k, e in after.items():
                if k in params:
                    params[k] = _value(e, k, str(diag_path), undetermined)
            for m in accepted:
                mid = m.get("id") if isinstance(m, dict) else None
                if not isinstance(mid, str):
                    raise InputError(f"{diag_path}: a mechanism without an 'id'")
                for k, e in (m.get("parameters") or {}).items():
                    params[k] = _value(e, k, str(diag_path), undetermined)
                if mid not in mech_ids:
                    mech_ids.append(mid)
            notes.append(f"mechanisms accepted by {diag_path}: {', '.join(m['id'] for m in accepted)} "
                         "(base parameters from its joint refit, parameters_after)")
    mechanisms = []
    for mid in mech_ids:
        try:
            mech = get(mid)
        except InputError as exc:
            raise InputError(f"{result_path}: {exc}") from None
        if is_sensor(mech):
            notes.append(f"left out: {mid} ({mech.name}) describes the bench's sensor, not the motor")
            continue
        missing = [k for k in mech.parameters if k not in params]
        if missing:
            raise InputError(f"{result_path}: mechanism '{mid}' lacks parameter(s) {', '.join(missing)}")
        folded = mech.fold_into_spec(params, spec)
        if folded is not None:  # a spec value the fit measured (the rotor inertia): into the spec exported
            before, spec = spec.inertia, folded
            notes.append(f"{mid} ({mech.name}): the measured rotor inertia J = {spec.inertia:.6g} kg.m2 "
                         f"(spec: {before:.6g}) is the one written for the load model")
            continue
        mechanisms.append(mech)
    base = [k for k in params if "." not in k]
    for need in ("Kv", "KF", "KFS", "TFc", "Ks", "KL0", "KAB"):
        if need not in base:
            raise InputError(f"{result_path}: parameters lack '{need}'")
    determined = set(undetermined.assume) - undetermined.used_assumptions
    if determined:
        k = sorted(determined)[0]
        raise InputError(f"--assume {k}: " + (f"the fit determined {k}; its value is the fit's"
                                              if k in params else f"no parameter '{k}' in {result_path}"))
    notes += list(dict.fromkeys(undetermined.notes))
    keep = set(base) | {k for m in mechanisms for k in m.parameters}
    params = {k: v for k, v in params.items() if k in keep}
    return IdentifiedMotor(spec=spec, params=params, mechanisms=tuple(mechanisms),
                           source=str(result_path), notes=notes)
