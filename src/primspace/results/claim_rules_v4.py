"""Version 4 of the rules that test the paper's claims (issue 42, "the scoreboard").

Three rules new or changed (:mod:`primspace.results.claims` quotes the sentences):

- ``infer_projection`` reads its whole sentence, "... yields good results already without
  any training, which means the initial distribution of projected points did not change
  much during the first part of the training." (:func:`projection_good_and_still`): the
  first half as version 1 did (projection's eval loss before any inference step below
  zero's after the last, at every q), and the second: the codes fitted in the first part
  stay close to their initial ``P m``, the mean over train samples of
  ``‖z_fit − P m‖ / ‖P m‖`` (:func:`code_drift`) below :data:`LITTLE_CHANGE` at every q.
  That needs the codes (an experiment directory's runs, or a summary's ``.codes.npz``,
  :mod:`primspace.results.codes`); without them the second half cannot be
  checked and the verdict is at most "partly". The threshold was named after the stored
  codes had been read (Adam's runs move about 0.06 of ``‖P m‖``, plain SGD's about 0.3).
- inter (:func:`inter_improved`): robustness compares the sample std (ddof 1,
  :func:`primspace.utils.stats.sample_std`) of the final loss over folds, where version 2 used
  the population std (ddof 0); the rest as version 2.
- the Summary's "Initialization of the latent variable by random linear projections
  improves intra- and inter-primitive generalization capabilities compared to
  conventional initialization methods." (:func:`intra_and_inter_improved`), reading intra
  and inter: holds when the abstract's intra rule
  (:func:`primspace.results.claim_rules_central.generalisation_improved`) and the inter
  rule both hold; partly when one of them holds or either holds partly; cannot be
  checked when one of the two experiments did not run.

Reads results (and codes) only; imports no experiment.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from primspace.results.claim_rules_central import generalisation_improved
from primspace.results.claim_rules_v2 import inter_measures, projection_good_untrained
from primspace.results.claim_verdicts import AGAINST, PARTLY, UNCHECKABLE, Outcome, verdict_word

__all__ = [
    "LITTLE_CHANGE",
    "CODE_DRIFT",
    "code_drift",
    "projection_good_and_still",
    "inter_improved",
    "intra_and_inter_improved",
]

#: "did not change much": the fitted codes' mean relative distance from their initial
#: ``P m`` (``‖z_fit − P m‖ / ‖P m‖``, averaged over train samples) below this.
LITTLE_CHANGE = 0.25
#: The key under which :func:`primspace.results.claims.check_claims` hands the rules the
#: codes' drift with intra's results: ``{"q40-s0": drift}`` of the projection runs.
CODE_DRIFT = "code_drift"

_PROJECTION_RUN = re.compile(r"projection-q(\d+)-s(\d+)$")


def _drift(fitted: np.ndarray, initial: np.ndarray) -> float:
    """Mean over rows of ``|fitted - initial| / |initial|`` (rows whose initial code is zero left out)."""
    norms = np.linalg.norm(initial.astype(np.float64), axis=1)
    keep = norms > 0
    moved = np.linalg.norm(fitted.astype(np.float64) - initial, axis=1)
    return float(np.mean(moved[keep] / norms[keep])) if keep.any() else float("nan")


def code_drift(codes: str | Path) -> dict[str, float]:
    """``{"q<q>-s<seed>": drift}`` of the intra projection runs' fit (the first part of the
    training), from an experiment directory (``runs/intra/projection-q*-s*/fit/latents.npy``
    and ``latents_init.npy``) or a summary's codes file (``NAME.codes.npz``); empty when
    neither holds any."""
    path, found = Path(codes), {}
    if path.is_dir():
        for fit in sorted(path.glob("runs/intra/projection-q*-s*/fit")):
            m = _PROJECTION_RUN.search(fit.parent.name)
            if m and (fit / "latents.npy").exists() and (fit / "latents_init.npy").exists():
                found[f"q{m[1]}-s{m[2]}"] = _drift(np.load(fit / "latents.npy"), np.load(fit / "latents_init.npy"))
        return found
    if not path.is_file():
        return found
    with np.load(path, allow_pickle=False) as arrays:
        for key in arrays["runs"] if "runs" in arrays.files else []:
            m = _PROJECTION_RUN.search(str(key))
            if m and str(key).startswith("intra/"):
                found[f"q{m[1]}-s{m[2]}"] = _drift(arrays[f"{key}/fit/latents"], arrays[f"{key}/fit/latents_init"])
    return found


def _halves(first: bool | str | None, second: bool | str | None) -> tuple[bool | str | None, str]:
    """A sentence of two halves: holds when both do, partly when one does, cannot be checked
    when neither can be; the direction: against where a half fails, else unchecked."""
    if first is True and second is True:
        return True, AGAINST
    if first is None and second is None:
        return None, UNCHECKABLE
    ok = PARTLY if True in (first, second) else False
    return ok, AGAINST if False in (first, second) or PARTLY in (first, second) else UNCHECKABLE


def projection_good_and_still(results: dict) -> Outcome:
    """The whole ``infer_projection`` sentence (module docstring): projection good untrained
    (at every q) and its codes still after the fit (drift below :data:`LITTLE_CHANGE` at every q)."""
    first = projection_good_untrained(results)
    drift = results.get(CODE_DRIFT) or {}
    runs = [r for r in results["runs"] if r["init"] == "projection"]
    qs = sorted({r["latent_dim"] for r in runs})
    at: dict[int, float] = {}
    for q in qs:
        values = [drift[f"q{q}-s{s}"] for s in sorted({r.get("seed", 0) for r in runs}) if f"q{q}-s{s}" in drift]
        if values:
            at[q] = float(np.mean(values))
    second = all(d < LITTLE_CHANGE for d in at.values()) if at else None
    ok, direction = _halves(first.ok, second)
    still = (
        "the fitted codes' mean ‖z_fit − P m‖ / ‖P m‖: "
        + ", ".join(f"q = {q}: {d:.2g}" for q, d in at.items())
        + f" (little from below {LITTLE_CHANGE:g})"
        if at
        else "the fitted codes are not here: their drift from P m cannot be checked"
    )
    by_q = {q: _halves((first.by_q or {}).get(q), (at[q] < LITTLE_CHANGE) if q in at else None)[0] for q in qs}
    return Outcome(ok, f"{first.numbers}; {still}", None, direction, by_q or None)


def inter_improved(results: dict) -> Outcome:
    """The inter rule of version 4: version 2's with the sample std (ddof 1) over folds."""
    return inter_measures(results, 1)


def intra_and_inter_improved(results: dict) -> Outcome:
    """The Summary's two-experiment sentence (module docstring); ``results`` holds ``intra``
    and ``inter`` (None where one did not run)."""
    intra, inter = results.get("intra"), results.get("inter")
    parts = {
        "intra": generalisation_improved(intra) if intra is not None else Outcome(None, "intra did not run"),
        "inter": inter_improved(inter) if inter is not None else Outcome(None, "inter did not run"),
    }
    ok = _both(parts["intra"].ok, parts["inter"].ok)
    numbers = "; ".join(f"{name}: {verdict_word(o.ok)} ({o.numbers})" for name, o in parts.items())
    inter_ok = parts["inter"].ok
    by_q = None
    if parts["intra"].by_q and inter_ok is not None:
        by_q = {q: _both(v, inter_ok) for q, v in parts["intra"].by_q.items()}
    return Outcome(ok, numbers, None, AGAINST, by_q)


def _both(a: bool | str | None, b: bool | str | None) -> bool | str | None:
    """Two verdicts that must both hold: None if either is, holds if both do, partly if
    either holds at least partly, else does not hold."""
    if a is None or b is None:
        return None
    if a is True and b is True:
        return True
    return PARTLY if PARTLY in (a, b) or True in (a, b) else False
