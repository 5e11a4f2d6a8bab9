"""Each run's steady samples reduced to shaft-angle cells as the run arrives: sufficient statistics.

A long high-rate log holds millions of samples, but the fit works on cells: the
samples of one run that share a shaft-angle bin (``bins_per_pitch`` per piston
pitch, over the whole revolution; :class:`motorid.identify.problem.Problem`).  Here
the cells are made run by run while the log is read, so that only the cells are
kept, never the samples:

- each input channel's cell mean (θ wrapped first, so a bin never straddles the
  wrap), the viscosity as its harmonic mean (the leakage goes as 1/μ), the
  parameter-free S(θ) averaged exactly;
- each measured channel's count, mean and scatter about the mean over its
  inliers; the outliers are found model-free before the reduction, as readings
  that stand out from the running median of their neighbours within the run
  (a Hampel test, :func:`motorid.robust.hampel_spikes`, at ``outlier_sigma``);
- each measured channel's noise level per run, model-free: the smaller of the
  pooled within-cell scatter (which also holds the slow change of the operating
  point over the run) and the RMS of first differences over √2 (which also holds
  the change between consecutive samples), both at least the sensor noise.

The fit (:func:`motorid.identify.cell_fit.fit_cells`) then weights each cell
mean by its count over σ² and holds these noise levels.
"""

from __future__ import annotations

import math

import numpy as np

from motorid.identify.types import MEASURED_CHANNELS, RUNNING_CHANNELS, VISCOSITY_MODES, CellStatistics
from motorid.model import Samples, make_samples
from motorid.robust import hampel_spikes, nanmedian


def give_back_free_memory() -> None:
    """Return the C heap's free pages to the system (glibc ``malloc_trim``; nothing elsewhere).

    The arrays of one long run are freed when the next arrives, but glibc keeps the pages
    (its mmap threshold rises with the sizes it has freed), so the process's resident
    memory would follow the longest run: 100 MB more at 3 M rows than at 1 M."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.malloc_trim(0)
    except (OSError, AttributeError):
        pass


#: samples of one call of the compiled S(θ) program: one shape for every run, however long
PORT_SUM_CHUNK = 1 << 16


def _port_sum(spec, theta: np.ndarray) -> np.ndarray:
    """S(θ) of each sample, from the one model function, in chunks of one padded shape (one
    compiled program, and temporaries the size of a chunk, not of the run)."""
    n = theta.size
    out = np.empty(n)
    zero = np.zeros(PORT_SUM_CHUNK)
    for a in range(0, n, PORT_SUM_CHUNK):
        part = theta[a:a + PORT_SUM_CHUNK]
        padded = np.concatenate([part, zero[: PORT_SUM_CHUNK - part.size]])
        s = make_samples(spec, padded, zero, zero, zero, zero, np.ones(PORT_SUM_CHUNK), acceleration=zero,
                         direction=zero, temperature=np.full(PORT_SUM_CHUNK, 40.0), time=zero)
        out[a:a + part.size] = np.asarray(s.port_sum)[: part.size]
    return out


class CellReducer:
    """Gathers the cells of running runs one run at a time (see the module doc)."""

    def __init__(self, spec, bins_per_pitch: int = 192, outlier_sigma: float = 5.0):
        self.spec, self.bins, self.k = spec, int(bins_per_pitch) * int(spec.pistons), float(outlier_sigma)
        self.parts: list = []
        self.noise = {c: {} for c in RUNNING_CHANNELS}
        self.outliers = {c: 0 for c in RUNNING_CHANNELS}
        self.rows = 0
        self.from_oil = 0

    def add_run(self, r: int, cols: dict, chosen: np.ndarray, acceleration, viscosity, direction: float,
                center: float, half: float) -> None:
        """Reduce run ``r``'s steady samples (positions ``chosen`` into its columns ``cols``;
        their acceleration [rad/s²] and smoothed viscosity [Pa·s]; the run's direction ±1;
        the center and half span [s] of its viscosity curve's time variable) to cells."""
        from motorid.io.logs import VISCOSITY_FROM_OIL

        two_pi = 2.0 * np.pi
        theta = np.mod(cols["theta_rad"][chosen], two_pi)
        b = np.minimum((theta / two_pi * self.bins).astype(np.int64), self.bins - 1)
        _, cell = np.unique(b, return_inverse=True)
        m = int(cell.max()) + 1
        n = np.bincount(cell, minlength=m).astype(float)
        mean = lambda x: np.bincount(cell, weights=x, minlength=m) / n  # noqa: E731
        time = cols["time_s"][chosen]
        temp = cols["oil_temp_C"][chosen]
        if np.isnan(temp).any():
            fill = nanmedian(temp)
            temp = np.where(np.isnan(temp), fill if math.isfinite(fill) else 40.0, temp)
        mu = np.asarray(viscosity, dtype=float)
        fields = {
            "theta": theta, "speed": cols["speed_rad_s"][chosen], "acceleration": np.asarray(acceleration, float),
            "p_a": cols["p_a_Pa"][chosen], "p_b": cols["p_b_Pa"][chosen], "p_case": cols["p_case_Pa"][chosen],
            "direction": np.full(chosen.size, float(direction)), "port_sum": _port_sum(self.spec, theta),
            "temperature": temp, "time": time,
        }
        part = {name: mean(x) for name, x in fields.items()}
        part["viscosity"] = n / np.bincount(cell, weights=1.0 / mu, minlength=m)
        part["n"] = n
        part["run"] = np.full(m, r)
        u = (time - center) / half
        part["basis"] = np.stack([mean(col) for col in np.polynomial.chebyshev.chebvander(u, VISCOSITY_MODES - 1).T],
                                 axis=1)
        if VISCOSITY_FROM_OIL in cols:
            self.from_oil += int(np.count_nonzero(np.asarray(cols[VISCOSITY_FROM_OIL])[chosen]))
        for c in RUNNING_CHANNELS:
            x = cols[MEASURED_CHANNELS[c]][chosen]
            spikes = hampel_spikes(x, k=self.k)
            ok = np.isfinite(x) & ~spikes
            self.outliers[c] += int(spikes.sum())
            shift = nanmedian(x[ok]) if ok.any() else 0.0
            y = np.where(ok, x - shift, 0.0)
            cnt = np.bincount(cell, weights=ok.astype(float), minlength=m)
            s1 = np.bincount(cell, weights=y, minlength=m)
            s2 = np.bincount(cell, weights=y * y, minlength=m)
            with np.errstate(invalid="ignore", divide="ignore"):
                part[c] = np.where(cnt > 0, shift + s1 / cnt, np.nan)
                within = np.where(cnt > 0, np.maximum(s2 - s1 * s1 / cnt, 0.0), 0.0)
            part["count_" + c], part["within_" + c] = cnt, within
            self.noise[c][r] = self._run_noise(np.where(ok, x, np.nan), cnt, within)
        self.parts.append(part)

    @staticmethod
    def _run_noise(x: np.ndarray, cnt: np.ndarray, within: np.ndarray) -> float:
        """σ of one sample of the run [SI]: the smaller of the pooled within-cell scatter and
        the first differences' RMS/√2 (NaN where neither has five degrees of freedom)."""
        est = []
        dof = cnt.sum() - np.count_nonzero(cnt)
        if dof >= 5:
            est.append(math.sqrt(within.sum() / dof))
        d = np.diff(x)
        d = d[np.isfinite(d)]
        if d.size >= 5:
            est.append(math.sqrt(float(np.mean(d * d)) / 2.0))
        return min(est) if est else math.nan

    def _join(self, key: str) -> np.ndarray:
        return np.concatenate([p[key] for p in self.parts]) if self.parts else np.zeros(0)

    def running_samples(self, runs):
        """(Samples of the cells, measured channels' cell means, frame rows (−1: none), run of each cell)."""
        fields = {name: self._join(name) for name in Samples._fields}
        running = Samples(**fields)
        measured = {c: self._join(c) for c in RUNNING_CHANNELS}
        run_of = self._join("run").astype(int)
        return running, measured, np.full(run_of.size, -1), run_of

    def statistics(self, n_runs: int) -> CellStatistics:
        noise = {}
        for c in RUNNING_CHANNELS:
            sig = np.full(n_runs, np.nan)
            for r, s in self.noise[c].items():
                sig[r] = s
            noise[c] = sig
        basis = (np.concatenate([p["basis"] for p in self.parts]) if self.parts
                 else np.zeros((0, VISCOSITY_MODES)))
        return CellStatistics(
            n=self._join("n"), counts={c: self._join("count_" + c) for c in RUNNING_CHANNELS},
            within={c: self._join("within_" + c) for c in RUNNING_CHANNELS}, noise=noise,
            viscosity_basis=basis, outliers=dict(self.outliers), rows=int(self.rows),
            viscosity_from_oil=int(self.from_oil))
