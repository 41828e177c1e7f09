"""``build_report``: the sections in order, written to ``OUT/report.html``."""

from __future__ import annotations

import datetime as _dt
from collections.abc import Callable
from pathlib import Path

from primspace.report import sections
from primspace.report.page import HtmlReport
from primspace.results.layout import META_FILE, REPORT_FILE, results_file
from primspace.results.readers import read_meta
from primspace.utils.errors import UserError, first_line

__all__ = ["build_report", "REPORT_FILE", "SECTIONS"]


#: The report's sections in order, each with the results file it reads (named in the
#: error when that file is not one this version can read). Each adds itself only if its
#: results exist.
SECTIONS: tuple[tuple[Callable[[Path, HtmlReport], None], str], ...] = (
    (sections.summary, "intra"),
    (sections.claims, "claims"),
    (sections.data, "data"),
    (sections.intra, "intra"),
    (sections.calibration, "intra"),
    (sections.clustering, "clustering"),
    (sections.success, "success"),
    (sections.inter, "inter"),
    (sections.tuning, "tune"),
    (sections.prediction, "predict"),
    (sections.scene_only, "scene"),
    (sections.act, "act"),
    (sections.composite, "composite"),
    (sections.latent_figures, "intra"),
    (sections.animations, "intra_animation"),
    (sections.appendix_a, "appendix_a"),
)


def build_report(out_dir: str | Path) -> Path:
    """Write ``out_dir/report.html`` from whatever results the directory holds.

    Reads results only (:mod:`primspace.report.sections`): it runs no experiment, so it
    can be rebuilt at any time, on any copy of the directory.

    Raises
    ------
    UserError
        If ``out_dir`` is not an experiment directory (no ``experiment.json``), or one
        of its results files is not one this primspace can read.
    """
    out_dir = Path(out_dir)
    if not (out_dir / META_FILE).exists():
        raise UserError(f"{out_dir}: not an experiment directory (no {META_FILE})")
    meta = read_meta(out_dir)
    report = HtmlReport(
        "primspace report",
        f"{out_dir.resolve().name} — preset {meta.get('preset', '?')} — "
        f"written {_dt.datetime.now().strftime('%Y-%m-%d %H:%M')}",
        root=out_dir,  # figures are embedded only from inside the experiment folder
    )
    for add_section, name in SECTIONS:
        try:
            add_section(out_dir, report)
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
            if isinstance(exc, UserError):
                raise
            raise UserError(
                f"{results_file(out_dir, name)}: not a results file this primspace can read "
                f"({type(exc).__name__}: {first_line(exc)}); re-run the experiment to rewrite it"
            ) from None
    sections.environment(out_dir, report)
    return report.write(out_dir / REPORT_FILE)
