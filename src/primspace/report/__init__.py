"""The HTML report of an experiment directory: one self-contained file, figures embedded.

``primspace report DIR`` (and every experiment, when it ends) writes ``DIR/report.html``:
a summary of the findings, then one section per experiment that has results in ``DIR``
(intra-primitive generalisation, clustering, success rates, inter-primitive
generalisation, latent-space figures, reconstructions, animations, the Appendix A
check), then the configuration, software versions and timings. PNG figures and the
animated GIFs (one per primitive) are embedded as base64, so the file can be mailed or
attached to a paper's supplementary material as it is.

The report reads results and computes nothing; it imports no experiment (only the
results readers of :mod:`primspace.results`).

- :mod:`~primspace.report.page`: :class:`HtmlReport`, the page writer.
- :mod:`~primspace.report.sections`: one function per section, reading results files.
- :mod:`~primspace.report.appendices`: the closing sections (Appendix A, the environment).
- :mod:`~primspace.report.build`: :func:`build_report`, the sections in order.
"""

from primspace.report.build import REPORT_FILE, build_report
from primspace.report.page import HtmlReport

__all__ = ["HtmlReport", "build_report", "REPORT_FILE"]
