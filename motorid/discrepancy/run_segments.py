"""Per-run statistics of per-sample arrays without a Python loop over the runs.

A campaign's samples, ordered run by run (a stable sort: time order within each run) and
restricted to a mask (a channel's inliers), form one contiguous segment per run.  Sums,
means, medians, ranges and lag-one autocorrelations per run are then a handful of vector
operations over every sample (``np.add.reduceat``, a ``lexsort``), however many runs there
are: what :func:`motorid.discrepancy.locate.locate` asks of every fit it judges, four or more
times per diagnosis.  Each function gives the numbers the obvious loop over runs gives (the
same operations, up to the order of floating-point summation).
"""

from __future__ import annotations

import numpy as np


class RunIndex:
    """The samples ordered run by run, in time order within each (a stable sort of the run numbers,
    made once): ``order``, and ``bounds`` where each run's slice of it starts and ends."""

    def __init__(self, run_of, n_runs: int):
        run_of = np.asarray(run_of, dtype=int)
        self.n_runs = int(n_runs)
        self.order = np.argsort(run_of, kind="stable")
        self.bounds = np.searchsorted(run_of[self.order], np.arange(n_runs + 1))

    def kept(self, mask=None) -> Segments:
        """The samples where ``mask`` holds (every sample: None), as run segments."""
        return Segments(self, mask)


class Segments:
    """The samples of a mask, run by run in time order.

    idx : their indices into the per-sample arrays; run : the run of each; n : samples per run;
    start : where each run's segment starts in ``idx``.
    """

    def __init__(self, index: RunIndex, mask=None):
        order = index.order
        keep = np.ones(order.size, bool) if mask is None else np.asarray(mask, bool)[order].copy()
        keep[:index.bounds[0]] = False  # run numbers outside 0 … n_runs − 1: in no run
        keep[index.bounds[-1]:] = False
        cum = np.concatenate([[0], np.cumsum(keep)])
        self.start = cum[index.bounds[:-1]]
        self.n = cum[index.bounds[1:]] - self.start
        self.idx = order[keep]
        self.run = np.repeat(np.arange(index.n_runs), self.n)
        self.n_runs = index.n_runs
        self._nonempty = self.n > 0
        # consecutive samples of one run: the pairs of a lag-one product or a difference
        self.same = self.run[:-1] == self.run[1:]

    def take(self, values) -> np.ndarray:
        """``values`` (per sample) at the kept samples, in segment order."""
        return np.asarray(values)[self.idx]

    def sum(self, x) -> np.ndarray:
        """Per-run sums of ``x`` (kept samples in segment order; 1-D, or 2-D with samples along
        axis 0) → (n_runs,) or (n_runs, m); 0 for an empty run."""
        x = np.asarray(x)
        out = np.zeros((self.n_runs,) + x.shape[1:], dtype=np.result_type(x.dtype, float))
        if x.shape[0]:
            out[self._nonempty] = np.add.reduceat(x, self.start[self._nonempty], axis=0)
        return out

    def mean(self, x) -> np.ndarray:
        """Per-run means (NaN for an empty run)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            s = self.sum(x)
            return s / (self.n if s.ndim == 1 else self.n[:, None])

    def spread(self, x) -> np.ndarray:
        """Per-run ``x`` minus its run's mean."""
        return np.asarray(x) - self.mean(x)[self.run]

    def extreme(self, x, largest: bool) -> np.ndarray:
        """Per-run maximum (``largest``) or minimum; NaN for an empty run."""
        out = np.full(self.n_runs, np.nan)
        if np.any(self._nonempty):
            f = np.maximum if largest else np.minimum
            out[self._nonempty] = f.reduceat(np.asarray(x, dtype=float), self.start[self._nonempty])
        return out

    def ptp(self, x) -> np.ndarray:
        return self.extreme(x, True) - self.extreme(x, False)

    def median(self, x) -> np.ndarray:
        """Per-run medians (np.median's: the mean of the two middle values of an even count);
        NaN for an empty run."""
        return segment_median(np.asarray(x, dtype=float), self.run, self.n, self.start, self.n_runs)

    def pair_median(self, x) -> np.ndarray:
        """Per-run medians of the differences of consecutive kept samples (np.diff within each
        run); NaN where a run has fewer than two."""
        x = np.asarray(x, dtype=float)
        d = np.diff(x)[self.same]
        run = self.run[:-1][self.same]
        n = np.bincount(run, minlength=self.n_runs)
        start = np.concatenate([[0], np.cumsum(n)[:-1]])
        return segment_median(d, run, n, start, self.n_runs)

    def unwrapped_ptp(self, theta) -> np.ndarray:
        """Per-run range of the unwrapped angle (np.unwrap within each run) [rad]."""
        theta = np.asarray(theta, dtype=float)
        dd = np.diff(theta)
        ddmod = np.mod(dd + np.pi, 2 * np.pi) - np.pi
        ddmod[(ddmod == -np.pi) & (dd > 0)] = np.pi
        correct = ddmod - dd
        correct[np.abs(dd) < np.pi] = 0.0
        correct[~self.same | ~np.isfinite(correct)] = 0.0  # no unwrapping across two runs, nor past a NaN
        total = np.concatenate([[0.0], np.cumsum(correct)])
        return self.ptp(theta + (total - total[self.start.clip(max=max(total.size - 1, 0))][self.run]))

    def lag1(self, z) -> np.ndarray:
        """Per-run lag-one autocorrelation of ``z`` about its run mean, clipped to [0, 0.95]; 0 for
        a run of fewer than four samples or without variance."""
        z = np.asarray(z, dtype=float)
        d = self.spread(z)
        sq = self.sum(d * d)
        prod = np.bincount(self.run[:-1][self.same], weights=(d[:-1] * d[1:])[self.same], minlength=self.n_runs)
        first, last = np.zeros(self.n_runs), np.zeros(self.n_runs)
        ne = self._nonempty
        first[ne] = d[self.start[ne]] ** 2
        last[ne] = d[self.start[ne] + self.n[ne] - 1] ** 2
        den = np.sqrt(np.maximum(sq - last, 0.0) * np.maximum(sq - first, 0.0))
        with np.errstate(invalid="ignore", divide="ignore"):
            rho = np.where(den > 0, np.clip(prod / den, 0.0, 0.95), 0.0)
        return np.where(self.n >= 4, rho, 0.0)


def segment_median(x, run, n, start, n_runs: int) -> np.ndarray:
    """Medians of ``x`` by ``run`` (sorted ascending, ``n`` per run from ``start``)."""
    out = np.full(n_runs, np.nan)
    ne = n > 0
    if not np.any(ne):
        return out
    sx = x[np.lexsort((x, run))]
    lo = start[ne] + (n[ne] - 1) // 2
    hi = start[ne] + n[ne] // 2
    out[ne] = 0.5 * (sx[lo] + sx[hi])
    nan = np.isnan(x)
    if nan.any():  # np.median's: NaN where a run holds one
        out[np.bincount(run[nan], minlength=n_runs) > 0] = np.nan
    return out
