"""Appendix A of the paper, checked numerically on the experiment's own data.

For P with entries N(0, 1/q) the paper shows E[Pa·Pb] = a·b and
Var[Pa·Pb] ≤ (3|a|²|b|² − (a·b)²)/q. :func:`run_appendix_a` draws 2000 matrices P per q
(:func:`primspace.model.latent.appendix_a_check`), with a and b two scaled, flattened motor
sequences of the data set (two of the same primitive, and two of different primitives,
as the paper's a and b), and writes ``results/appendix_a.json``; the report prints it.
"""

from __future__ import annotations

import numpy as np

from primspace.experiments.workspace import ExperimentDir

__all__ = ["run_appendix_a", "APPENDIX_A_DRAWS", "appendix_a_dims"]

#: Matrices P drawn per pair and q.
APPENDIX_A_DRAWS = 2000


def appendix_a_dims(cluster_latent_dim: int) -> list[int]:
    """The latent sizes q checked: 10, 20, 40 and the preset's clustering q."""
    return sorted({10, 20, 40} | {int(cluster_latent_dim)})


def run_appendix_a(exp: ExperimentDir, *, overwrite: bool = False) -> dict:
    """Check Appendix A on ``exp``'s data; write and return ``results/appendix_a.json``.

    Done once per experiment directory: an existing result is returned as it is
    (unless ``overwrite``). Each q draws from its own seed (``random_state=q``).
    """
    from primspace.data import JointScaler
    from primspace.model.latent import appendix_a_check

    if not overwrite and (done := exp.read_results("appendix_a")) is not None:
        return done
    data = exp.dataset()
    with exp.stage("appendix A"):
        flat = JointScaler().fit_transform(data.motor).reshape(len(data), -1)
        first = np.flatnonzero(data.labels == data.labels[0])
        other = np.flatnonzero(data.labels != data.labels[0])
        pairs = [("same primitive", first[0], first[-1])]
        if other.size:
            pairs.append(("different primitives", first[0], other[0]))
        rows = []
        for name, i, j in pairs:
            for q in appendix_a_dims(exp.preset.cluster_latent_dim):
                check = appendix_a_check(flat[i], flat[j], q, n_draws=APPENDIX_A_DRAWS, random_state=q)
                rows.append({"pair": name, "a": int(i), "b": int(j)} | check)
    results = {"n_draws": APPENDIX_A_DRAWS, "rows": rows}
    exp.write_results("appendix_a", results)
    return results
