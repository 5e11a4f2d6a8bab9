"""The synthetic ISO 4392 bench: test plans (protocols), a time simulator, sensors.

- :mod:`protocols` read and validate a test plan TOML into run plans
- :mod:`sensors`   what the DAQ does to a true signal: offset, noise, quantization
- :mod:`truth`     the true parameters (and extra physics) of a simulated motor
- :mod:`dynamics`  load-driven shaft motion: Karnopp stick-slip, flow-fed inlet
- :mod:`simulate`  run protocols on the one model and write a campaign
- :mod:`cli`       ``motorid simulate``

Every torque and flow comes from :func:`motorid.model.predict`,
:func:`motorid.model.predict_breakaway` and :func:`motorid.model.static_friction_limit`.
"""
