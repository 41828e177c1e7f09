"""The API reference builds from the docstrings without network (``make docs``:
``python docs/build_api.py build/api``), and documents the public names a user reaches
for first."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytest.importorskip("pdoc")


@pytest.mark.slow
def test_the_api_reference_builds_and_names_the_public_classes(tmp_path):
    out = tmp_path / "api"
    result = subprocess.run(
        [sys.executable, str(ROOT / "docs" / "build_api.py"), str(out)], capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr[-3000:]
    assert (out / "index.html").is_file()
    pages = {p.relative_to(out).as_posix(): p.read_text(encoding="utf-8") for p in out.rglob("*.html")}
    for module in ("primspace/data.html", "primspace/train.html", "primspace/cluster.html"):
        assert module in pages, sorted(pages)[:20]
    text = "\n".join(pages.values())
    for name in ("MotionDataset", "AutoDecoder", "LowRankSubspaceClustering", "TrainConfig", "ModelConfig"):
        assert f'id="{name}"' in text, name
    # numpydoc sections are rendered, not shown as raw underlined text
    assert "Parameters\n----------" not in text
