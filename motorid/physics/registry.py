"""The registry of extra physics: every named mechanism the 1992 model leaves out.

One line per mechanism in :data:`_ALL`; :mod:`motorid.model` composes the ones a
truth file, a fit or the discrepancy search names, and :mod:`motorid.discrepancy`
searches over :func:`all_mechanisms`.  Each mechanism declares its parameters
(``"<id>.<name>"``, with unit, meaning, sign and typical size), its reference,
the physics in words and its residual signature (:class:`CatalogMechanism`).

The ``typical`` sizes (starting values and prior scales of fits) are chosen for
an 80 cm³/rev motor running up to about 3000 rpm and 250 bar, where each
mechanism is noticeable but modest: about 1-3 % of the channel it acts on.

Mechanism ids and parameter names are written in files (truth TOMLs,
diagnosis.json): never rename one.  Mechanisms are singletons: compiled kernels
are cached by mechanism, and unpickling one gives back the object here.
"""

from __future__ import annotations

from motorid.errors import InputError
from motorid.physics.base import CatalogMechanism
from motorid.physics.compressibility import CompressibilityFlow
from motorid.physics.friction import CasePressureFriction, StribeckFriction
from motorid.physics.hydrodynamic import HydrodynamicTorque
from motorid.physics.leakage import GapDeformation, TurbulentLeakage
from motorid.physics.lubrication import MixedLubricationFriction, PressureSpeedTorque
from motorid.physics.mode import PumpModeFriction
from motorid.physics.relief import ReliefValve
from motorid.physics.ripple import MisalignmentRipple
from motorid.physics import sensors, spec_errors
from motorid.physics.sensors import TorqueOffset
from motorid.physics.film_heating import FilmHeating
from motorid.physics.viscosity import PressureViscosity
from motorid.physics.volumetric import FillingLoss

_ALL = (
    StribeckFriction(),
    HydrodynamicTorque(),
    TurbulentLeakage(),
    CompressibilityFlow(),
    MisalignmentRipple(),
    TorqueOffset(),
    CasePressureFriction(),
    PressureViscosity(),
    MixedLubricationFriction(),  # physics that measured loss maps show (issue 20)
    PressureSpeedTorque(),
    FillingLoss(),
    PumpModeFriction(),
    FilmHeating(),  # the viscous loss bending over at high speed (real maps, issue 20)
    ReliefValve(),  # flow past the motor above a cracking pressure (the MBARI recordings, issue 20)
    GapDeformation(),  # leakage growing faster than the pressure (probe F's radial maps, issue 20)
    *spec_errors.MECHANISMS,  # displacement_error, leak_phase, inertia_error
    *sensors.MECHANISMS,  # flow_meter_gain_a/b/case, torque_meter_gain, flow_meter_offset_a/b/case,
    #                       sensor_lag_<channel>
)

#: every mechanism by id (singletons)
CATALOG: dict[str, CatalogMechanism] = {m.id: m for m in _ALL}


def get(mech_id: str) -> CatalogMechanism:
    """The registry's mechanism ``mech_id``; :class:`InputError` naming the known ones otherwise."""
    try:
        return CATALOG[mech_id]
    except (KeyError, TypeError):
        raise InputError(f"unknown mechanism '{mech_id}'; known: {', '.join(CATALOG)}") from None


def all_mechanisms() -> list[CatalogMechanism]:
    """Every mechanism of the registry, in registry order."""
    return list(CATALOG.values())
