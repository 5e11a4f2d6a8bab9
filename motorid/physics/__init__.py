"""The physics of Bartos 1992, one module per phenomenon, pure JAX, SI units.

- :mod:`kinematics` piston angles, the exact swept sums, ripple approximations
- :mod:`torque`     pressure, inertia, viscous and Coulomb friction torques
- :mod:`flow`       swept flow, port-to-case and cross-port leakage, net flows
- :mod:`oil`        viscosity and density of the oil against temperature
"""
