"""The one-command demo (``make demo``): simulate, learn, cluster, judge, report.

At demo scale (:data:`primspace.experiments.presets.PRESETS` ``["demo"]``) on a 2-core
CPU, in about five minutes when its cores are idle: generate the demo data set with the
MuJoCo arm, run the intra-primitive experiment (four latent initialisations and the
calibrated start, two latent sizes), cluster the learned codes and the raw trajectories,
judge the generated motions in the simulator, and write the HTML report. Whether the
paper's qualitative result (projection-initialised codes infer to a lower loss than zero
and random ones) holds at this scale is stated plainly in the summary and the report,
whichever way it comes out.

This module sits above both the experiments (which compute and write results) and the
report (which reads them): neither imports it, and the report imports no experiment.
"""

from __future__ import annotations

import time
from pathlib import Path

from primspace.experiments.clustering import run_clustering
from primspace.experiments.intra import run_intra
from primspace.experiments.presets import PRESETS
from primspace.experiments.success import run_success
from primspace.experiments.workspace import ExperimentDir
from primspace.report import build_report
from primspace.results.layout import DATA_FILE, LEARNED_CODES, META_FILE, RESULT_FILE
from primspace.results.tables import final, qualitative_check
from primspace.utils.progress import announce

__all__ = ["earlier_results", "run_demo"]


def run_demo(
    out_dir: str | Path,
    *,
    workers: int = 2,
    progress: bool | None = None,
    device: str | None = None,
    threads: int | None = None,
) -> str:
    """Run the demo into ``out_dir``; return a text summary (report path, table, verdict).
    ``device``, ``threads``: each run's (None: the demo preset's, auto and 1)."""
    start = time.perf_counter()
    preset = PRESETS["demo"].with_overrides(device=device, threads=threads)
    reused = earlier_results(out_dir)
    exp = ExperimentDir(out_dir, preset, workers=workers, progress=progress)
    if reused:
        announce(f"demo: {reused}", enabled=progress)
    announce(f"demo 1/5: the simulated data set ({exp.path})", enabled=progress)
    exp.dataset()
    announce("demo 2/5: intra-primitive runs (fit on 20%, infer the rest, per init and q)", enabled=progress)
    intra = run_intra(exp)
    announce("demo 3/5: clustering of the learned codes", enabled=progress)
    clustering = run_clustering(exp)
    announce("demo 4/5: success of the generated motions, judged by the simulator", enabled=progress)
    success = run_success(exp)
    announce("demo 5/5: the report", enabled=progress)
    report = build_report(exp.path)
    took = f"{time.perf_counter() - start:.0f} s" + (f" ({reused})" if reused else "")
    return _summary(exp, intra, clustering, success, report, took)


def earlier_results(out_dir: str | Path) -> str | None:
    """What an earlier demo left in ``out_dir`` that this one reuses instead of computing it again,
    in one line (None: nothing, the demo starts from scratch)."""
    path = Path(out_dir)
    runs = len(list(path.glob(f"runs/*/{RESULT_FILE}"))) if (path / META_FILE).is_file() else 0
    data = (path / DATA_FILE).is_file()
    if not data and not runs:
        return None
    what = " and ".join(p for p in ("its data set" if data else "", f"{runs} finished run(s)" if runs else "") if p)
    return f"reusing {what} from an earlier demo in {path} (remove that folder or give --out elsewhere to start over)"


def _summary(exp, intra, clustering, success, report, took: str) -> str:
    """The text ``primspace demo`` prints: report path, a table per init, the verdict."""
    finals = {}
    for r in intra["runs"]:
        finals[(r["init"], r["latent_dim"])] = final([h["loss"] for h in r["infer"]])
    dims = sorted({q for _, q in finals})
    inits = [i for i in exp.preset.inits if any((i, q) in finals for q in dims)]
    latent_rows = clustering.get("latent", [])
    acc = {row["init"]: row["accuracy"] for row in latent_rows if row["codes"] == LEARNED_CODES}
    initial = [row for row in latent_rows if row["codes"] != LEARNED_CODES]
    succ = {i: r["overall"] for i, r in success.get("generated", {}).items()}
    header = (
        f"{'init':<11}" + "".join(f"{'eval loss q=' + str(q):>16}" for q in dims) + f"{'cluster acc':>13}{'success':>9}"
    )
    lines = [header, "-" * len(header)]
    for init in inits:
        cells = "".join(f"{finals.get((init, q), float('nan')):>16.4g}" for q in dims)
        lines.append(f"{init:<11}{cells}{acc.get(init, float('nan')):>13.3f}{succ.get(init, float('nan')):>9.2f}")
    for row in initial:
        lines.append(
            f"  cluster acc of the {row['init']} codes before training ({row['codes']}): {row['accuracy']:.3f}"
        )
    ok, text = qualitative_check(intra)
    verdict = {True: "HOLDS", False: "DOES NOT HOLD", None: "cannot be checked"}[ok]
    return "\n".join(
        [f"primspace demo finished in {took}", f"report: {report}", ""]
        + lines
        + [
            "",
            f"paper's qualitative result (projection's eval loss below zero and random): {verdict} at demo "
            "scale (a smoke test of the pipeline, not evidence: docs/results.md has the paper-scale verdicts)",
            f"  {text}",
        ]
    )
