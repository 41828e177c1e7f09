"""The report's closing sections: Appendix A's identities checked by sampling, and the
configuration, software versions and timings of the experiment directory.

Like every section (:mod:`primspace.report.sections`), each reads the directory's results
files and computes nothing.
"""

from __future__ import annotations

import json
import platform
from pathlib import Path

from primspace.report.page import HtmlReport
from primspace.results.layout import results_file
from primspace.results.readers import read_meta, read_results

__all__ = ["appendix_a", "environment"]


def appendix_a(out_dir: Path, report: HtmlReport) -> None:
    """Appendix A's identities, checked by sampling (``results/appendix_a.json``)."""
    results = read_results(out_dir, "appendix_a")
    if results is None and not any(results_file(out_dir, n).exists() for n in ("intra", "inter", "data")):
        return  # nothing has run here yet
    report.section("Appendix A: random projections keep inner products")
    report.paragraph(
        "For P with entries N(0, 1/q), the paper shows E[Pa·Pb] = a·b and "
        f"Var[Pa·Pb] ≤ (3|a|²|b|² − (a·b)²)/q. Checked by drawing {results['n_draws'] if results else 2000} matrices P, "
        "with a and b two scaled, flattened motor sequences of this data set. 'mean z' is the deviation of the sample "
        "mean from a·b in standard errors; the exact variance for Gaussian P is (|a|²|b|² + (a·b)²)/q."
    )
    if results is None:
        report.note(
            f"Not computed here: results/{results_file(out_dir, 'appendix_a').name} is written by the intra and "
            "inter experiments, and an older primspace did not write it. Re-run "
            f"`primspace experiment intra --out {out_dir}` (finished runs are skipped) to compute it.",
            "warn",
        )
        return
    rows = [
        [
            r["pair"],
            r["latent_dim"],
            r["dot"],
            r["mean"],
            r["mean_z"],
            r["var"],
            r["var_exact"],
            r["var_bound"],
            "yes" if r["var"] <= r["var_bound"] else "no",
        ]
        for r in results["rows"]
    ]
    report.table(["pair", "q", "a·b", "mean Pa·Pb", "mean z", "var", "exact var", "bound", "var ≤ bound"], rows)


def environment(out_dir: Path, report: HtmlReport) -> None:
    """Software versions of the machine writing the report, timings per stage, experiment.json."""
    import numpy
    import torch

    from primspace import __version__

    meta = read_meta(out_dir)
    report.section("Configuration, versions, timings")
    versions = [
        ["primspace", __version__],
        ["python", platform.python_version()],
        ["numpy", numpy.__version__],
        ["torch", torch.__version__],
        ["machine", f"{platform.machine()} {platform.system()}"],
    ]
    try:
        import mujoco

        versions.append(["mujoco", mujoco.__version__])
    except ImportError:  # pragma: no cover - a dependency
        pass
    report.table(["software", "version"], versions)
    timings = meta.get("timings", {})
    if timings:
        report.table(["stage", "seconds"], [[k, float(v)] for k, v in timings.items()], "Wall-clock time per stage.")
    report.code(json.dumps(meta, indent=2))
