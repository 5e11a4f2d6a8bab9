"""JAX set-up shared by every module: float64 and a persistent compile cache.

The cache lives in ``$MOTORID_CACHE_DIR`` (default ``~/.cache/motorid/jax``) so
that a second CLI run does not pay the XLA compiles again; it is kept below
``$MOTORID_CACHE_MAX_MB`` (default 2048) by :mod:`motorid._cachesize`.
"""

import os

import jax

jax.config.update("jax_enable_x64", True)

_cache = os.environ.get(
    "MOTORID_CACHE_DIR", os.path.join(os.path.expanduser("~"), ".cache", "motorid", "jax")
)
CACHE_DIR = _cache  # also holds the serialized executables of motorid._aot
try:
    os.makedirs(_cache, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", _cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
except (OSError, AttributeError):  # read-only home: run without the cache
    pass
else:  # a size cap, looked at once a day (motorid._cachesize; MOTORID_CACHE_MAX_MB)
    try:
        from motorid._cachesize import prune_now_and_then

        prune_now_and_then(_cache)
    except Exception:  # noqa: BLE001 - housekeeping never stops a run
        pass
