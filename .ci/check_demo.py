"""CI: check what `make demo` wrote (the shipped demo path, not a test preset).

Usage: python .ci/check_demo.py DEMO_OUT SUMMARY_TXT
Fails (exit 1, one line per problem) unless the report has every section with its
figures embedded as PNG and one small animated GIF per primitive (the report < 8 MB), the
results files hold every grid run with no failure (and the data summary, Appendix A and
latent-figure results the report reads), every recorded motion passes the judge, and the
printed summary gives a verdict.
"""

import base64
import io
import json
import re
import sys
from pathlib import Path

from PIL import Image

out, summary = Path(sys.argv[1]), Path(sys.argv[2]).read_text()
problems = []
html = (out / "report.html").read_text(encoding="utf-8") if (out / "report.html").exists() else ""
for title in ("Summary", "The paper&#x27;s claims, checked", "Intra-primitive", "Subspace clustering",
              "Success rates of generated motions", "Configuration, versions, timings"):
    if title not in html:
        problems.append(f"report.html: no section '{title}'")
pngs = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
if len(pngs) < 8:
    problems.append(f"report.html: {len(pngs)} embedded figures, expected at least 8")
for i, data in enumerate(pngs):
    raw = base64.b64decode(data)
    if not raw.startswith(b"\x89PNG\r\n\x1a\n") or len(raw) < 5000:
        problems.append(f"report.html: figure {i} is not a drawn PNG ({len(raw)} bytes)")
gifs = re.findall(r'src="data:image/gif;base64,([A-Za-z0-9+/=]+)"', html)  # one animation per primitive
if len(gifs) < 7:
    problems.append(f"report.html: {len(gifs)} embedded animations, expected one per primitive (7)")
for i, data in enumerate(gifs):
    raw = base64.b64decode(data)
    with Image.open(io.BytesIO(raw)) as gif:
        frames = gif.n_frames if gif.format == "GIF" else 0
    if frames < 2 or len(raw) > 300_000:
        problems.append(f"report.html: animation {i} is not an animated GIF under 300 kB ({frames} frames, {len(raw)} bytes)")
if len(html) > 8_000_000:
    problems.append(f"report.html: {len(html) / 1e6:.1f} MB, expected a light report (< 8 MB)")
intra = json.loads((out / "results/intra.json").read_text())
preset = json.loads((out / "experiment.json").read_text())["preset_config"]
expected = len(preset["inits"]) * len(preset["latent_dims"]) * len(preset["seeds"])  # 10 since 0.5 (calibrated)
if intra["failures"] or len(intra["runs"]) != expected:
    problems.append(f"results/intra.json: {len(intra['runs'])} runs (expected {expected}), failures {intra['failures']}")
success = json.loads((out / "results/success.json").read_text())
if success["recorded"] is None or success["recorded"]["overall"] != 1.0:
    problems.append("results/success.json: not every recorded motion passes the judge")
for name in ("data", "appendix_a", "intra_latent"):  # what the report's Data, Appendix A and latent figures read
    if not (out / f"results/{name}.json").exists():
        problems.append(f"results/{name}.json: not written (the report reads it, it computes nothing)")
# the demo's numbers, pinned (tests/test_demo_pinned.py runs the same preset; CI deselects it there
# and checks the shipped demo's own results here instead of training the demo twice)
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from conftest import pinned_for_this_cpu  # noqa: E402
from test_demo_pinned import PINNED_BY_CPU, _flat, _numbers  # noqa: E402

import pytest  # noqa: E402

clustering = json.loads((out / "results/clustering.json").read_text())
got = _flat(_numbers(intra, clustering, success))
pinned = _flat(pinned_for_this_cpu(PINNED_BY_CPU, "demo numbers", vendor=True))
unpinned = set() if any("calibrated" in k for k in pinned) else {k for k in got if "calibrated" in k}
if got.keys() - unpinned != pinned.keys():
    problems.append(f"results: the pinned demo numbers' keys differ: {sorted(got.keys() ^ pinned.keys())[:5]}")
off = [k for k in pinned if got.get(k) != pytest.approx(pinned[k], rel=1e-6, abs=1e-12)]
if off:
    problems.append(f"results: {len(off)} demo numbers differ from tests/test_demo_pinned.json, e.g. {off[:3]}")
if not re.search(r"paper's qualitative result .*: (HOLDS|DOES NOT HOLD)", summary):
    problems.append("demo summary: no verdict on the paper's qualitative result")
if problems:
    print("\n".join(problems))
    sys.exit(1)
print(
    f"demo check: report with {len(pngs)} figures, {len(gifs)} animations, {expected} intra runs, recorded motions all pass, "
    f"{len(pinned)} pinned numbers equal; ok"
)
