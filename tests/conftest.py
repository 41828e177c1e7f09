"""Shared test helpers: run the ``primspace`` command in-process and capture what it says."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")  # before anything imports mujoco


def pytest_collection_modifyitems(config, items):
    """Under pytest-xdist (``make test``: ``--dist loadfile --no-loadscope-reorder``), the
    modules with the most ``slow`` tests first, each module's tests in their order: a worker
    takes one module at a time, so the longest modules start at once and the short ones fill
    in the end. A run in one process keeps the files' order."""
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return
    slow: dict[str, int] = {}
    for item in items:
        module = item.nodeid.split("::")[0]
        slow[module] = slow.get(module, 0) + (item.get_closest_marker("slow") is not None)
    items.sort(key=lambda item: -slow[item.nodeid.split("::")[0]])  # stable: a module stays in one piece


@dataclass
class CliResult:
    code: int
    out: str
    err: str


@pytest.fixture
def run_cli(capsys):
    """Call ``primspace ARGS...`` in this process; return exit code, stdout and stderr."""
    from primspace.cli import main

    def run(*args: str) -> CliResult:
        capsys.readouterr()
        try:
            main([str(a) for a in args])
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        captured = capsys.readouterr()
        return CliResult(code, captured.out, captured.err)

    return run


def assert_user_error(result: CliResult, *fragments: str) -> None:
    """Exit status 2, one line on stderr naming every fragment, no traceback."""
    assert result.code == 2, (result.code, result.out, result.err)
    lines = [line for line in result.err.strip().splitlines() if line.strip()]
    assert len(lines) == 1, result.err
    assert "Traceback" not in result.err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])


# ------------------------------------------------------------------ a tiny simulated data set

#: The tiny data set's generator settings: two block positions per primitive, 14 motions of
#: 31 steps, no images (seconds to generate).
TINY_DATA = dict(block_x=(0.45, 0.55), block_y=(0.0,), block_size=(0.05,), length=31, images=False)


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory):
    """The path of a tiny simulated data set (:data:`TINY_DATA`, seed 0), generated once per
    test module: the experiments' tests run their grids on it."""
    from primspace.sim.generate import GenerationConfig, generate_dataset

    path = tmp_path_factory.mktemp("data") / "tiny.h5"
    generate_dataset(GenerationConfig(**TINY_DATA), seed=0, out=path, progress=False)
    return path


@pytest.fixture(scope="module")
def loss_motor_set():
    """9 synthetic motor sequences of 10 steps, 4 joints (the loss tests' data)."""
    from test_train import primitives

    return primitives(3, seed=0, T=10, J=4)


@pytest.fixture(scope="module")
def loss_image_set():
    """6 synthetic sequences of 6 steps, 3 joints, 8x8 frames (the loss tests' data)."""
    from test_train import primitives

    return primitives(2, seed=1, T=6, J=3, images=True)


@pytest.fixture
def grid_only(monkeypatch):
    """``run_intra`` without its steps after the grid (probe, Appendix A check, figures, animations),
    for the tests of the grid itself: tests/test_experiments.py checks those steps on its own grid."""
    from primspace.experiments import intra

    for name in ("run_probe", "run_appendix_a", "write_animations"):
        monkeypatch.setattr(intra, name, lambda *args, **kwargs: None)
    monkeypatch.setattr(intra.figures, "draw_intra", lambda *args, **kwargs: [])


# ------------------------------------------------------------------ figures (PNG files)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def read_png(path) -> np.ndarray:
    """The PNG at ``path`` as an (H, W, 3) uint8 RGB array, transparency composited on white."""
    import matplotlib.image as mpimg
    import numpy as np

    with open(path, "rb") as fh:
        assert fh.read(8) == PNG_SIGNATURE, f"{path} is not a PNG file"
    a = np.asarray(mpimg.imread(path), dtype=np.float64)  # floats in [0, 1]
    if a.ndim == 2:
        a = a[..., None]
    if a.shape[-1] in (2, 4):  # grey or RGB with alpha
        a = a[..., :-1] * a[..., -1:] + (1.0 - a[..., -1:])
    if a.shape[-1] == 1:
        a = np.repeat(a, 3, axis=-1)
    return np.round(a * 255).astype(np.uint8)


def colour_pixels(rgb, colour, tol: int = 40) -> int:
    """How many pixels lie within ``tol`` (every channel, 0-255) of ``colour`` (a matplotlib colour)."""
    import numpy as np
    from matplotlib.colors import to_rgb

    target = np.round(np.array(to_rgb(colour)) * 255)
    return int((np.abs(rgb.astype(np.int16) - target) <= tol).all(axis=-1).sum())


def figure_stats(rgb) -> dict:
    """``ink``: fraction of non-white pixels; ``coloured``: pixels of a clearly chromatic colour
    (axes, ticks and text are black or grey, so these are the data); ``colours``: distinct colours."""
    import numpy as np

    px = rgb.reshape(-1, 3).astype(np.int16)
    return {
        "ink": float((px < 245).any(axis=1).mean()),
        "coloured": int(((px.max(axis=1) - px.min(axis=1)) > 60).sum()),
        "colours": len(np.unique(px, axis=0)),
    }


def assert_figure(
    path,
    *,
    height=(200, 1500),
    width=(300, 2500),
    min_ink: float = 0.04,
    min_coloured: int = 500,
    min_colours: int = 300,
    colours=(),
    min_colour_pixels: int = 100,
) -> np.ndarray:
    """The PNG at ``path`` is a drawn figure, not a blank or empty one: its pixel size lies in the
    given ranges, at least ``min_ink`` of it is not white (a matplotlib figure with empty, labelled
    axes measured 0.03), at least ``min_coloured`` pixels are chromatic (an empty one has none) and
    it has ``min_colours`` distinct colours (an empty one has ~255 greys of anti-aliased text);
    every colour in ``colours`` covers at least ``min_colour_pixels`` pixels. Returns the RGB array."""
    rgb = read_png(path)
    h, w = rgb.shape[:2]
    assert height[0] <= h <= height[1] and width[0] <= w <= width[1], (str(path), rgb.shape)
    stats = figure_stats(rgb)
    assert stats["ink"] >= min_ink, (str(path), stats)
    assert stats["coloured"] >= min_coloured, (str(path), stats)
    assert stats["colours"] >= min_colours, (str(path), stats)
    for colour in colours:
        n = colour_pixels(rgb, colour)
        assert n >= min_colour_pixels, (str(path), colour, n)
    return rgb


def cpu_class(vendor: bool = False) -> str:
    """The widest SIMD set NumPy dispatches to on this CPU: "avx512", "avx2" or "other";
    with ``vendor``, AMD's AVX-512 CPUs apart: "avx512-amd".

    NumPy's transcendental functions (sin, cos, ...) and the BLAS kernels round in the last
    bit differently per SIMD set, so numbers pinned bit for bit (hashes of generated data,
    losses after hundreds of epochs) are recorded per class: the same code gives the same
    bits on every CPU of a class, not across classes. Simulated data are the same on Intel
    and AMD AVX-512 CPUs; training is not (measured: every demo loss differs in the last
    digits between an Intel AVX-512 CPU and an AMD EPYC Zen 4), so training pins ask for
    the vendor too.
    """
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # NumPy 1
        from numpy.core._multiarray_umath import __cpu_features__ as features
    if features.get("AVX512F") and features.get("AVX512_SKX"):
        return "avx512-amd" if vendor and _cpu_vendor() == "AuthenticAMD" else "avx512"
    return "avx2" if features.get("AVX2") else "other"


def _cpu_vendor() -> str:
    """``vendor_id`` of /proc/cpuinfo ("GenuineIntel", "AuthenticAMD"; "" where unknown)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            return next((line.split(":", 1)[1].strip() for line in f if line.startswith("vendor_id")), "")
    except OSError:
        return ""


def pinned_for_this_cpu(table: dict, what: str, vendor: bool = False):
    """``table[cpu_class(vendor)]``; a skip naming the classes pinned when this CPU's is not one."""
    cls = cpu_class(vendor)
    if cls not in table:
        pytest.skip(f"{what}: pinned on {', '.join(sorted(table))} CPUs; this one is {cls}")
    return table[cls]


def _one_thread():
    from primspace.train.config import thread_limit

    with thread_limit(1):
        yield


@pytest.fixture(scope="module")
def one_thread():
    """One torch and BLAS thread for a module's tests (tiny models on two shared cores run many
    times slower with a second thread), the process's settings restored after; a module asks for
    it with ``pytestmark = pytest.mark.usefixtures("one_thread")``."""
    yield from _one_thread()


@pytest.fixture
def one_thread_each():
    """The same per test: for comparisons bit for bit with processes that run one thread (the CPU
    kernels may split their sums by thread)."""
    yield from _one_thread()
