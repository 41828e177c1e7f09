"""The linear probe of every intra run's codes (issue 14: "structure as a number").

For each finished intra-primitive run (every init, q and seed), the cross-validated R² of
a ridge regression from codes to the data's generative factors (``params``: block x, y
and size), within each primitive (:func:`primspace.probe.linear_probe`), for three sets of
codes: the fitted codes of the train part, the inferred codes of the eval part (θ frozen),
and the initial codes of every sample before any training (``P m`` for projection). This
is the paper's latent-encoding figure (the PCA of one primitive's codes coloured by the
block's position) made quantitative. Written to ``results/probe.json``; data without
``params`` (LASA, imported demonstrations) have nothing to probe and write nothing.
"""

from __future__ import annotations

from primspace.experiments.runs import initial_codes, load_codes
from primspace.experiments.workspace import ExperimentDir
from primspace.results.layout import PROBE_RESULTS

__all__ = ["run_probe"]

# the sets of codes probed: name -> (which samples, which codes)
_CODE_SETS = (("fitted", "train", "learned"), ("inferred", "eval", "learned"), ("initial", "all", "initial"))


def run_probe(exp: ExperimentDir, results: dict) -> dict | None:
    """Probe every run of ``results`` (the intra results); write and return ``results/probe.json``."""
    from primspace.probe import linear_probe

    data = exp.dataset()
    if data.params is None or not results["runs"]:
        return None
    rows = []
    for r in sorted(results["runs"], key=lambda r: (r["latent_dim"], r["seed"], r["init"])):
        learned, is_train = load_codes(exp, r["init"], r["latent_dim"], r["seed"])
        initial = initial_codes(exp, r["init"], r["latent_dim"], r["seed"])
        row = {"init": r["init"], "latent_dim": r["latent_dim"], "seed": r["seed"]}
        for name, part, which in _CODE_SETS:
            mask = {"train": is_train, "eval": ~is_train, "all": is_train | ~is_train}[part]
            codes = (learned if which == "learned" else initial)[mask]
            probe = linear_probe(codes, data.params[mask], data.labels[mask], factor_names=list(data.param_names))
            row[name] = probe.to_dict()
        rows.append(row)
    out = {"factor_names": list(data.param_names), "label_names": list(data.label_names), "runs": rows}
    exp.write_results(PROBE_RESULTS, out)
    return out
