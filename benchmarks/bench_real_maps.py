"""Real measured maps that may not be shipped: held-out errors of motorid and the classical models.

    MOTORID_REAL_MAPS=FOLDER python benchmarks/run.py --only bench_real_maps

FOLDER holds the downloaded files (benchmarks/real_maps/README.md: ``A6VM.mat``, ``V32HL56.csv``);
their channel maps and motor specs are in benchmarks/real_maps/.  For each file present:
``motorid fit`` and ``motorid diagnose`` in fresh processes (wall time and peak RSS from
/usr/bin/time), and the held-out comparison each writes (K-fold, extrapolation in ΔP and in
speed, % of each channel's span).  Without FOLDER (or with none of the files in it) the section
is kept as last measured, so that ``make bench`` without the data does not erase it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
MAPS = HERE / "real_maps"
PARTS = HERE / "sections" / "real_maps"  # one subsection per map, kept while its file is not at hand
DATA = {  # name → (file in FOLDER, what it is)
    "A6VM": ("A6VM.mat", "Bosch Rexroth A6VM 28.1 cm³/rev bent-axis unit, four quadrants, 401 × 127 "
                         "interpolated grid (jwills801/PTO-Comparison, no licence)"),
    "V32HL56": ("V32HL56.csv", "variable-displacement axial piston pump V32HL56, five settings 12-57 cm³/rev, "
                               "pump mode only, absolute pressures (mitgandhi/Efficiency_plots, no licence)"),
}
KINDS = (("kfold", "K-fold"), ("extrapolate_pressure", "ΔP"), ("extrapolate_speed", "speed"))


def _timed(cmd) -> tuple[float, float]:
    """(wall s, peak RSS GiB) of one fresh process; a failure raises with its last lines."""
    proc = subprocess.run(["/usr/bin/time", "-f", "@@%e %M", *map(str, cmd)], capture_output=True, text=True,
                          cwd=ROOT, env=dict(os.environ, MOTORID_QUIET="1"))
    if proc.returncode:
        raise RuntimeError(f"{' '.join(map(str, cmd))} failed:\n{proc.stderr[-1500:]}")
    wall, kb = [x for x in proc.stderr.splitlines() if x.startswith("@@")][-1][2:].split()
    return float(wall), float(kb) / 2**20


def _rows(comparison: dict) -> list[str]:
    models = comparison["models"]
    chans = [c for c in ("torque", "q_a", "q_b", "q_case") if any(c in m.get("kfold", {}) for m in models.values())]
    out = ["| model | " + " | ".join(chans) + " |", "|---|" + "---|" * len(chans)]
    for name, m in models.items():
        cells = []
        for c in chans:
            vals = [m.get(k, {}).get(c, {}).get("percent_of_span") for k, _ in KINDS]
            cells.append(" \\| ".join("—" if v is None else f"{v:.2f}" for v in vals))
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    return out


def run(quick: bool = False) -> str:
    folder = os.environ.get("MOTORID_REAL_MAPS")
    present = {k: Path(folder) / f for k, (f, _) in DATA.items()} if folder else {}
    present = {k: p for k, p in present.items() if p.is_file()}
    PARTS.mkdir(parents=True, exist_ok=True)
    for name, path in present.items():  # a map not at hand keeps its last measurement
        (PARTS / f"{name}.md").write_text(_measure(name, path))
    parts = [(PARTS / f"{name}.md").read_text() for name in DATA if (PARTS / f"{name}.md").exists()]
    if not parts:
        return ("## Real maps that may not be shipped (bench_real_maps)\n\nNot measured: set MOTORID_REAL_MAPS to "
                "the folder of the downloaded files (benchmarks/real_maps/README.md).\n")
    return "\n".join(HEADER + parts)


HEADER = ["## Real maps that may not be shipped (bench_real_maps)", "",
             "`MOTORID_REAL_MAPS=FOLDER python benchmarks/run.py --only bench_real_maps` (study: "
             "benchmarks/bench_real_maps.py; channel maps and specs: benchmarks/real_maps/). Each command a "
             "fresh process, compile cache as left by earlier runs. Held-out RMS error in % of each channel's "
             "span: K-fold \\| extrapolation in ΔP \\| in speed (fit on |ΔP| or |ω| up to the 70th percentile, "
             "predict the rest). The files are not in the repository (no licence); the README there says where "
             "they are. A map not at hand when the study runs keeps its last measurement "
             "(benchmarks/sections/real_maps/).", ""]


def _measure(name: str, path: Path) -> str:
    """The subsection of one map: fit and diagnose in fresh processes, their held-out comparisons."""
    py = sys.executable
    common = [path, "--channels", MAPS / f"{name}.channels.toml", "--motor", MAPS / f"{name}.motor.toml",
              "--force", "--quiet"]
    with tempfile.TemporaryDirectory() as tmp:
        fit_s, fit_m = _timed([py, "-m", "motorid", "fit", *common, "--out", Path(tmp) / "fit"])
        dg_s, dg_m = _timed([py, "-m", "motorid", "diagnose", *common, "--out", Path(tmp) / "dg"])
        fit = json.loads((Path(tmp) / "fit" / "result.json").read_text())
        dg = json.loads((Path(tmp) / "dg" / "diagnosis.json").read_text())
    sel = dg.get("selection", {})
    lines = [f"### {name}: {DATA[name][1]}", "",
             f"{fit['table']['points']:,} points; `motorid fit` {fit_s:.1f} s, {fit_m:.2f} GiB; `motorid diagnose` "
             f"{dg_s:.1f} s, {dg_m:.2f} GiB" + (f" ({sel['points_note']})" if sel.get("points_note") else "") + ".",
             "", "Named by diagnose: " + (", ".join(f"`{m['id']}`" for m in dg["mechanisms"]) or "none")
             + f"; unexplained structures: {len(dg.get('unexplained') or [])}.", ""]
    if fit.get("comparison"):
        lines += ["`motorid fit` (the 1992 model) and the classical models:", ""] + _rows(fit["comparison"]) + [""]
    if dg.get("comparison"):
        lines += ["`motorid diagnose` (with what it named, and its empirical terms held out):", ""]
        lines += _rows({"models": dict(list(dg["comparison"]["models"].items())[:1])}) + [""]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(run())
