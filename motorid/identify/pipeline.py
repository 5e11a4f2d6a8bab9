"""From log files to a fit: read, validate, extract, least squares, (emcee)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

from motorid.identify.least_squares import fit_least_squares
from motorid.identify.types import FitOptions, FitResult


@dataclass
class Identification:
    ls: FitResult
    bayes: object  # BayesResult or None
    dataset: object
    frame: object
    seconds: float
    priors: dict


def load_campaign(paths: Sequence, spec, channels=None):
    """Read and validate the logs, then extract steady samples and breakaway events."""
    from motorid.identify.extract import extract
    from motorid.io.logs import read_logs

    frame = read_logs([str(p) for p in paths], spec, channels)
    return frame, extract(frame, spec)


def viscosity_model_warning(frame, dataset, ls) -> str:
    """A warning where the viscosity of running samples came from the oil model, not a
    viscometer: K_v scales with μ and K_L0, K_AB with 1/μ, one for one, and the
    standard errors do not hold the oil model's own error ("" where it did not)."""
    from motorid.io.logs import VISCOSITY_FROM_OIL

    if frame is None or VISCOSITY_FROM_OIL not in frame.columns or not dataset.n_running:
        return ""
    share = float(frame[VISCOSITY_FROM_OIL].to_numpy()[dataset.frame_index].mean())
    affected = [k for k in ("Kv", "KL0", "KAB") if ls.identifiable.get(k)]
    if share <= 0 or not affected:
        return ""
    return (f"the viscosity of {100 * share:.0f} % of the running samples comes from oil_temp_C and the spec's "
            f"[oil] (Walther, ASTM D341; density ρ15/(1 + β(T − 15 °C))), not a viscometer: "
            f"{', '.join(affected)} carry that model's error one for one (K_v ∝ μ, K_L0 and K_AB ∝ 1/μ), "
            f"and their std does not include it")


def identify(paths: Sequence, spec, bayes: bool = False, options: FitOptions | None = None,
             mechanisms: Sequence = (), seed: int = 0, progress: bool | None = None,
             dataset=None, frame=None, channels=None) -> Identification:
    """The main job: a least-squares fit of every parameter the logs identify, and
    with ``bayes`` an emcee posterior started from it."""
    t0 = time.time()
    if dataset is None:
        frame, dataset = load_campaign(paths, spec, channels)
    ls = fit_least_squares(dataset, spec, mechanisms=mechanisms, options=options)
    note = viscosity_model_warning(frame, dataset, ls)
    if note:
        ls.warnings.append(note)
    post, priors = None, {}
    if bayes and ls.free:
        from motorid.identify.bayes import prior_scale, sample_posterior

        post = sample_posterior(ls, spec, seed=seed, progress=progress)
        priors = {k: (f"HalfNormal(scale={prior_scale(k, spec, ls.mechanisms):.3g})"
                      if not k.startswith("KL_") else "Normal(0, 1)") for k in ls.free}
    return Identification(ls, post, dataset, frame, time.time() - t0, priors)
