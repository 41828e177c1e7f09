"""The UEA/UCR ``.ts`` importer: files, several files, a folder; labels and channels; errors located."""

import importlib.util
from pathlib import Path

import numpy as np

BENCHMARK = Path(__file__).resolve().parents[1] / "benchmarks" / "eval_auto_tau.py"

MULTI = """# two channels, two classes
@problemName Tiny
@timeStamps false
@missing false
@univariate false
@dimensions 2
@equalLength true
@seriesLength 3
@classLabel true walk run
@data
1.0,2.0,3.0:-1.5,0.25,4e-1:walk
0.5,0.5,0.5:7,8,9:run
"""


def _benchmark():
    spec = importlib.util.spec_from_file_location("eval_auto_tau", BENCHMARK)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_benchmark_reads_ts_values_and_labels(tmp_path):
    """The benchmark's reading of a .ts file (n, T, channels), pinned before the reader moved."""
    path = tmp_path / "Tiny_TRAIN.ts"
    path.write_text(MULTI, encoding="utf-8")
    series, labels = _benchmark().read_ts(path)[:2]
    np.testing.assert_array_equal(
        np.stack(series), [[[1.0, -1.5], [2.0, 0.25], [3.0, 0.4]], [[0.5, 7.0], [0.5, 8.0], [0.5, 9.0]]]
    )
    assert list(labels) == ["walk", "run"]
