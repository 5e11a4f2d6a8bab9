"""Everything read and written at the edge, in the units of the outside world.

SI inside motorid; units are converted here, once, and every bad value raises
:class:`motorid.errors.InputError` naming the file, column, run or key.

- :mod:`logs`     bench logs (BENCH_LOG_FORMAT.md CSV, and the header dialects of other benches)
- :mod:`spec`     motor spec TOML → :class:`motorid.model.MotorSpec`
- :mod:`tomlfile` reading TOML files and validating their numbers (specs, protocols, truths)
- :mod:`formats`  DAQ files (.mat v5/v7.3, HDF5, Parquet, xlsx, TDMS, MDF4, any CSV) through a channel map
- :mod:`channel_map` the channel-map TOML: names, units, sign conventions, gridded maps
- :mod:`tables`   operating-point tables (loss maps, ISO 4409 style) → SI point arrays
- :mod:`results`  result.json / diagnosis.json: read, and written whole or not at all

Nothing heavy is imported here: ``import motorid.io`` costs nothing; import the module you need.
"""
