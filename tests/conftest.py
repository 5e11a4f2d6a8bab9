import os

os.environ.setdefault("MPLBACKEND", "Agg")

import motorid  # noqa: E402,F401  (float64 before any jax array exists)
