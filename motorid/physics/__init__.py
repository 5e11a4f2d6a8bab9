"""The physics, one module per phenomenon family, pure JAX, SI units.

The 1992 model (Bartos, JPL TDA Progress Report 42-111):

- :mod:`kinematics` piston angles, the exact swept sums, ripple approximations
- :mod:`torque`     pressure, inertia, viscous and Coulomb friction torques
- :mod:`flow`       swept flow, port-to-case and cross-port leakage, net flows
- :mod:`oil`        viscosity and density of the oil against temperature

Extra mechanisms (:mod:`base` their interface, :mod:`registry` the list):

- :mod:`friction`        Stribeck friction, case-pressure seal friction
- :mod:`hydrodynamic`    churning torque ∝ ω²
- :mod:`ripple`          1× and 2× shaft-order torque ripple (misalignment)
- :mod:`leakage`         turbulent (orifice) leakage ∝ √ΔP
- :mod:`compressibility` dead-volume compression flow ∝ ΔP·|ω|
- :mod:`viscosity`       pressure-viscosity (Barus) effect on the laminar leakage
- :mod:`sensors`         torque transducer zero offset
"""
