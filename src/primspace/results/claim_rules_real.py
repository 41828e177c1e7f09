"""The verdict of the intra protocol on real recordings, one per data set, and the measures that
explain it. The rule was written before any run (version 1) and is versioned like the paper's
rules (:mod:`primspace.results.claims`).

The paper's central claim (its abstract): codes started at a random linear projection of the
motion generalise better to unobserved samples than codes started at zero. On real recordings
(``primspace experiment intra --preset real --data FILE.h5``: 20 % of each class fitted, the rest
inferred with θ frozen) the rule (:data:`RULE`, :func:`projection_below_zero`) reads each init's
final held-out inference loss (the eval part's loss after the last inference epoch) per seed and
compares projection's mean over seeds with zero's: it **holds** when projection's is lower by
more than the spread over seeds, the larger of the two sample standard deviations (ddof 1);
otherwise it **does not hold**, either as a tie (the difference within that spread; a tie never
counts as an improvement) or reversed (zero's lower by more than the spread: against the paper).
With one seed there is no spread and the verdict is "cannot be checked". At several q, it must
hold at every q.

What explains a verdict (:func:`diagnostics`), from the codes a summary keeps
(:mod:`primspace.results.codes`) and its data summary:

- **the codes' scale**: the mean norm of the projection codes before training, ``‖P m‖``, over
  the mean norm of the codes zero's fit learned (the scale the decoder settles on when nothing
  sets it), and projection's fitted codes' mean relative drift from ``P m``;
- **the data's dimension**: ``T x J``, the values ``P`` maps to ``q``;
- **the projection's conditioning**: the singular values of the matrix of projected codes
  ``P m`` over all samples (centred), as the ratio of the largest to the smallest (σ1/σq) and
  the share of the variance along the first direction (σ1² / Σσ²); a large ratio means the
  projected codes fill a few of the q directions, so inference must move them along the rest.

Reads results only; imports no experiment.
"""

from __future__ import annotations

import numpy as np

from primspace.results.claim_verdicts import AGAINST, AS_SAID, UNCHECKABLE

__all__ = [
    "RULE",
    "RULE_VERSION",
    "CLAIM",
    "eval_losses",
    "projection_below_zero",
    "diagnostics",
]

#: The sentence tested (the paper's abstract, verbatim).
CLAIM = (
    "Experimental results demonstrate substantial improvement in generalisation abilities for unobserved "
    "samples in the case of initialization of latent variables with random linear projection of motor data over "
    "initialization with zero or random values."
)
#: The rule's version (bumped with a changed rule; the earlier kept beside it).
RULE_VERSION = 1
#: The rule, as the docs print it.
RULE = (
    f"v{RULE_VERSION}: projection's final held-out inference loss (eval part, θ frozen, mean over seeds) below "
    "zero's by more than the spread over seeds (the larger of the two sample standard deviations, ddof 1), at "
    "every q; otherwise a tie (within the spread) or reversed (zero lower by more than it); written before the runs"
)


def eval_losses(intra: dict) -> dict[int, dict[str, dict[int, float]]]:
    """``{q: {init: {seed: final eval loss}}}`` of an intra result (a directory's or a summary's)."""
    out: dict = {}
    for run in intra.get("runs", []):
        curve = [h["loss"] for h in run.get("infer", []) if h.get("loss") is not None]
        if curve:
            out.setdefault(run["latent_dim"], {}).setdefault(run["init"], {})[int(run["seed"])] = float(curve[-1])
    return {q: out[q] for q in sorted(out)}


def _compare(zero: dict[int, float], projection: dict[int, float]) -> dict:
    """The rule at one q (module docstring), on ``{seed: final eval loss}`` of each; also in how
    many of the seeds both ran projection ended lower (``lower_in``, said beside the verdict)."""
    z, p = np.asarray(list(zero.values())), np.asarray(list(projection.values()))
    paired = sorted(set(zero) & set(projection))
    numbers = {"zero": float(z.mean()), "projection": float(p.mean()), "seeds": int(min(z.size, p.size))}
    numbers["lower_in"] = [sum(projection[s] < zero[s] for s in paired), len(paired)]
    if min(z.size, p.size) < 2:
        return numbers | {"verdict": "cannot be checked", "detail": "one seed: no spread"}
    spread = float(max(z.std(ddof=1), p.std(ddof=1)))
    difference = float(z.mean() - p.mean())
    numbers |= {"spread": spread, "difference": difference, "ratio": float(z.mean() / p.mean())}
    if difference > spread:
        return numbers | {"verdict": "holds", "detail": "projection lower"}
    detail = "reversed: zero lower" if -difference > spread else "tie: within the spread"
    return numbers | {"verdict": "does not hold", "detail": detail}


def projection_below_zero(intra: dict) -> dict:
    """The rule's verdict on one data set's intra result: ``verdict``, ``direction``, ``text`` and
    the numbers at each q (``by_q``: zero's and projection's mean, the difference, the spread)."""
    by_q = {
        q: _compare(d["zero"], d["projection"])
        for q, d in eval_losses(intra).items()
        if "zero" in d and "projection" in d
    }
    if not by_q:
        return {"verdict": "cannot be checked", "direction": UNCHECKABLE, "by_q": {}, "text": "not run"}
    verdicts = [c["verdict"] for c in by_q.values()]
    if "cannot be checked" in verdicts:
        verdict, direction = "cannot be checked", UNCHECKABLE
    elif all(v == "holds" for v in verdicts):
        verdict, direction = "holds", AS_SAID
    else:
        verdict, direction = "does not hold", AGAINST
    text = "; ".join(
        f"q = {q}: {c['detail']} (zero {c['zero']:.3g}, projection {c['projection']:.3g}"
        + (f", difference {c['difference']:.2g} against spread {c['spread']:.2g}" if "spread" in c else "")
        + f"; projection lower in {c['lower_in'][0]} of {c['lower_in'][1]} seeds)"
        for q, c in by_q.items()
    )
    return {"verdict": verdict, "direction": direction, "by_q": by_q, "text": text}


def _runs_of(codes: dict, init: str, q: int) -> list[dict]:
    """The stored runs of ``init`` at ``q`` (one per seed), from :func:`~primspace.results.codes.read_codes`."""
    return [run for key, run in codes["runs"].items() if key.startswith(f"intra/{init}-q{q}-s")]


def _mean_norm(z: np.ndarray) -> float:
    return float(np.linalg.norm(np.asarray(z, dtype=np.float64), axis=1).mean())


def _spectrum(z: np.ndarray) -> np.ndarray:
    centred = np.asarray(z, dtype=np.float64) - np.mean(z, axis=0)
    return np.linalg.svd(centred, compute_uv=False)


def diagnostics(codes: dict, data: dict, q: int) -> dict:
    """What explains the verdict (module docstring), each a mean over the stored seeds.

    Parameters
    ----------
    codes : dict
        A codes file as :func:`~primspace.results.codes.read_codes` reads it.
    data : dict
        The summary's ``data`` (``length``, ``n_joints``).
    q : int
        The latent size.

    Returns
    -------
    dict
        ``values`` (T x J), ``q``, ``pm_norm`` (mean ‖P m‖ over all samples), ``zero_norm``
        (mean norm of zero's fitted codes), ``projection_norm`` (projection's fitted codes),
        ``scale_ratio`` (``pm_norm / zero_norm``), ``drift`` (projection's fitted codes' mean
        ‖z − P m‖ / ‖P m‖), ``condition`` (σ1/σq of the centred P m), ``top_share``
        (σ1² / Σσ²), and ``seeds``; a value is None where its runs are not stored.
    """
    projection, zero = _runs_of(codes, "projection", q), _runs_of(codes, "zero", q)
    out = {"values": int(data.get("length", 0)) * int(data.get("n_joints", 0)) or None, "q": q}
    out["seeds"] = len(projection)
    initial = [np.concatenate([r["fit/latents_init"], r["infer/latents_init"]]) for r in projection]
    spectra = [_spectrum(z) for z in initial]
    out["pm_norm"] = float(np.mean([_mean_norm(z) for z in initial])) if initial else None
    out["zero_norm"] = float(np.mean([_mean_norm(r["fit/latents"]) for r in zero])) if zero else None
    out["projection_norm"] = float(np.mean([_mean_norm(r["fit/latents"]) for r in projection])) if projection else None
    out["scale_ratio"] = out["pm_norm"] / out["zero_norm"] if initial and zero and out["zero_norm"] else None
    drifts = [
        np.mean(
            np.linalg.norm(r["fit/latents"] - r["fit/latents_init"], axis=1)
            / np.maximum(np.linalg.norm(r["fit/latents_init"], axis=1), 1e-12)
        )
        for r in projection
    ]
    out["drift"] = float(np.mean(drifts)) if drifts else None
    out["condition"] = float(np.mean([s[0] / max(s[-1], 1e-300) for s in spectra])) if spectra else None
    out["top_share"] = float(np.mean([s[0] ** 2 / np.sum(s**2) for s in spectra])) if spectra else None
    return out
