import os

os.environ.setdefault("MPLBACKEND", "Agg")

import motorid._jaxconfig  # noqa: E402,F401  (float64 before any jax array exists)

from functools import lru_cache  # noqa: E402
from pathlib import Path  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
PROTOCOLS = REPO / "protocols"

DEMO_TRUTH = {"Kv": 5000.0, "KF": 3e-3, "KFS": 1.5e-2, "TFc": 3.0, "Ks": 1.0,
              "KL0": 5e-14, "KL_a1": 0.15, "KL_b1": 0.08, "KAB": 2e-14}


def map_motor_toml(temp_C: float) -> str:
    """The demo motor (9 pistons, 80 cm³/rev, ISO VG 46) with an assumed oil temperature, for loss-map
    tables that hold none."""
    return f"""
[motor]
name = "map-9"
pistons = 9
displacement_cm3 = 80.0
[oil]
name = "ISO VG 46"
nu40_cSt = 46.0
nu100_cSt = 6.8
density15_kg_m3 = 875.0
temp_C = {temp_C}
"""


@lru_cache(maxsize=16)
def simulated(pistons: int = 9, displacement_cm3: float = 80.0, seed: int = 1,
              protocols: tuple = ("constant_speed", "constant_pressure", "startability"),
              truth_items: tuple | None = None, mechanisms: tuple = ()):
    """A simulated campaign (frame, spec, truth params) from the repo's protocols, cached per session."""
    from motorid.bench.protocols import load_protocol
    from motorid.bench.simulate import simulate_campaign
    from motorid.bench.truth import parse_truth
    from motorid.model import MotorSpec, OilSpec

    spec = MotorSpec(name=f"test-{pistons}", pistons=pistons, displacement=displacement_cm3 * 1e-6,
                     inertia=0.005, oil=OilSpec())
    params = dict(truth_items) if truth_items else dict(DEMO_TRUTH)
    table = {"parameters": {k: v for k, v in params.items() if "." not in k}}
    for key, value in params.items():
        if "." in key:
            mid, name = key.split(".", 1)
            table.setdefault("mechanisms", {}).setdefault(mid, {})[name] = value
    truth = parse_truth(table, "test truth")
    files = {p.stem.split("_", 1)[1]: p for p in PROTOCOLS.glob("*.toml")}
    chosen = [load_protocol(files[name]) for name in protocols]
    camp = simulate_campaign(chosen, spec, truth, seed=seed)
    return camp.frame, spec, params


def concealed(name: str):
    """A shipped concealed campaign of synthetic_data/concealed/: (spec, dataset, base fit, truth document)."""
    import tomllib

    from motorid.identify.least_squares import fit_least_squares
    from motorid.identify.pipeline import load_campaign
    from motorid.io.spec import load_motor_spec

    root = REPO / "synthetic_data" / "concealed"
    spec = load_motor_spec(root / name / "motor.toml")
    _, ds = load_campaign([root / name / "campaign.csv.gz"], spec)
    truth = tomllib.loads((root / "truths" / f"{name}.toml").read_text())
    return spec, ds, fit_least_squares(ds, spec), truth
