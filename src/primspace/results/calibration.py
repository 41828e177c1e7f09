"""The calibrated start against the raw projection, zero and pca, read from the intra results.

Calibrated projection (:class:`primspace.model.calibration.CodeCalibration`) starts a new code at
a ridge map of ``P m`` instead of ``P m``: :func:`calibration_table` compares its eval loss
with the other starts' per q, beside how far the fitted codes moved from ``P m`` and how well
the map predicts them; :func:`calibration_verdict` says whether it never loses. Reads
results only (through :mod:`primspace.results.tables`); imports no experiment.
"""

from __future__ import annotations

from primspace.results.tables import final, mean_std

__all__ = ["CALIBRATION_COMPARED", "CALIBRATION_TOLERANCE", "calibration_table", "calibration_verdict"]

#: The starts the calibration table compares, in its column order.
CALIBRATION_COMPARED = ("projection", "calibrated", "zero", "pca")


def _eval_losses(results: dict) -> dict:
    """``{(q, init): [(start, final) per seed]}`` of the intra runs' eval part."""
    out: dict = {}
    for r in results["runs"]:
        losses = [h["loss"] for h in r["infer"]]
        out.setdefault((r["latent_dim"], r["init"]), []).append((losses[0], final(losses)))
    return out


def calibration_table(results: dict) -> tuple[list[str], list[list]] | None:
    """Calibrated projection against the raw projection, zero and pca, per q (mean ± std
    over seeds): how far the fitted codes moved from ``P m`` and how well the ridge map
    predicts them (projection fit's ``calibration``), and the eval loss at the start and
    the end of inference. None without calibrated runs."""
    losses = _eval_losses(results)
    qs = sorted({q for q, init in losses if init == "calibrated"})
    if not qs:
        return None
    diag: dict = {}
    for r in results["runs"]:
        if r["init"] == "projection" and r.get("calibration"):
            diag.setdefault(r["latent_dim"], []).append(r["calibration"])
    rows = []
    for q in qs:
        d = diag.get(q, [])
        row = [
            q,
            len(losses[(q, "calibrated")]),
            mean_std([x["movement"] for x in d]),
            mean_std([x["identity_r2"] for x in d]),
            mean_std([x["heldout_r2"] for x in d]),
        ]
        for which in (0, 1):
            row += [
                mean_std([v[which] for v in losses[(q, init)]]) if (q, init) in losses else "—"
                for init in CALIBRATION_COMPARED
            ]
        rows.append(row)
    columns = ["q", "seeds", "movement ‖Z−Pm‖/‖Pm‖", "R² of P m", "held-out R² of the map"]
    columns += [f"start {i}" for i in CALIBRATION_COMPARED] + [f"final {i}" for i in CALIBRATION_COMPARED]
    return columns, rows


#: "Never loses": calibrated's final eval loss at most this factor above the better of
#: projection's and zero's (5 %: the spread of reruns that differ in the last bits).
CALIBRATION_TOLERANCE = 1.05


def calibration_verdict(results: dict) -> tuple[bool | None, str]:
    """Does calibrated never lose, seed by seed and at every q, to the raw projection or to
    zero: its final eval loss at most :data:`CALIBRATION_TOLERANCE` x the lower of theirs?"""
    by: dict = {}
    for r in results["runs"]:
        by.setdefault((r["latent_dim"], r["seed"]), {})[r["init"]] = final([h["loss"] for h in r["infer"]])
    verdicts, lines = [], []
    for (q, seed), d in sorted(by.items()):
        if "calibrated" not in d or "projection" not in d:
            continue
        others = [i for i in ("projection", "zero") if i in d]
        ok = d["calibrated"] <= CALIBRATION_TOLERANCE * min(d[i] for i in others)
        verdicts.append(ok)
        lines.append(
            f"q={q}, seed {seed}: calibrated {d['calibrated']:.3g}, "
            + ", ".join(f"{i} {d[i]:.3g} ({d[i] / d['calibrated']:.3g}x)" for i in others)
        )
    if not verdicts:
        return None, "no calibrated runs beside projection ones"
    return all(verdicts), (
        f"calibrated within {CALIBRATION_TOLERANCE:g}x of the better of projection and zero in "
        f"{sum(verdicts)} of {len(verdicts)} runs: " + "; ".join(lines)
    )
