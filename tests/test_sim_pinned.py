"""Pinned numbers of the simulator: generated arrays, scripted paths and the judge's verdicts.

The constants below were recorded from the code before the primitives became classes
(issue 12, item 4). A reshape of :mod:`primspace.sim` must leave every one unchanged:
same seed, same bytes. If a change is *meant* to alter the data or the judge, bump
``JUDGE_VERSION`` where the judge changes and record new constants deliberately.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np
import pytest

from conftest import pinned_for_this_cpu
from primspace.sim.generate import GenerationConfig, generate_dataset
from primspace.sim.primitives import PRIMITIVES, script_motion
from primspace.sim.scene import Scene
from primspace.sim.success import JUDGE_VERSION, evaluate

#: 7 primitives x 2 x positions x 2 sizes = 28 motions, jittered by seed 0, with 24 x 32 frames.
WITH_IMAGES = GenerationConfig(
    block_x=(0.45, 0.55), block_y=(0.0,), block_size=(0.04, 0.06), length=31, height=24, width=32
)
#: Joints only, another grid, T = 41, exact grid positions, a subset of primitives.
NO_IMAGES = GenerationConfig(
    block_x=(0.50,),
    block_y=(-0.08, 0.08),
    block_size=(0.05,),
    length=41,
    images=False,
    jitter=0.0,
    primitives=("pull", "touch_right", "circle_ccw"),
)

PINNED = {
    "with_images": {
        "motor": "131be908e0bf789872d42ac266353ed898a142e7",
        "labels": "a07702f14625f351cae74f73a288a8ea5365749f",
        "params": "6512d387b1b7bb4c467a1a8e0fec70a524680b21",
        "images": "722f52aab2473442f34db7e416243472c2b41b13",
    },
    "no_images": {
        "motor": "a3f2a44ab328b244fdbe1e618fbc51c4c561abcd",
        "labels": "928f412c5fc7f60dc1f89c78b9ef7ff4a2d03046",
        "params": "1b3096b43f2ba796890c41c2b19944f6e2cd53bb",
        "images": None,
    },
}
PINNED_SCRIPTS = "a94d98a4d3d7f27197bac8de95875eb56e67099a"

#: The values above were recorded on an AVX-512 CPU. On AVX2-only CPUs NumPy's sin and cos
#: round differently in the last bit (the circles' arcs), so the scripted paths and the
#: motor of the set with circles differ there; recorded on an AMD EPYC (AVX2) with the code
#: of 0.3.1, which gives these same values on that CPU.
BY_CPU = {
    "avx512": (PINNED, PINNED_SCRIPTS),
    "avx2": (
        {**PINNED, "with_images": {**PINNED["with_images"], "motor": "147f38d6e8cf0777bbdbd195746a3ef5a726fa4f"}},
        "6230d7842643fbaceb64b236196700cc96f05701",
    ),
}
#: (pass/fail per verdict, SHA-1 of every verdict with its criteria and measures)
PINNED_VERDICTS = {
    "own": ("1" * 28, "8f7678a532efbf844ac66d28451d2f43b43b6250"),
    # sample-major: each of the 28 motions judged as each of the 7 primitives (a diagonal)
    "confusion": (
        "1000000100000010000001000000010000001000000100000010000000100000010000001000000100000001"
        "000000100000010000001000000010000001000000100000010000000100000010000001000000100000001000000100000010000001",
        "c1be0c87280756a2cae9a6dda6b50d0750f615ea",
    ),
    # sample-major: five perturbations of each motion (see perturbed_verdicts)
    "perturbed": (
        "10010101101001010010101101001010010101101011010110101101011010110101101011010110101111011110111101111010010100101001010010100101001010010100",
        "e0c082a2ad1411c3c0b6fcbb79c000674f0ef6e7",
    ),
}


def sha1(array) -> str | None:
    if array is None:
        return None
    return hashlib.sha1(np.ascontiguousarray(array).tobytes()).hexdigest()


def digest(verdicts) -> tuple[str, str]:
    """A pass/fail string (``1``/``0`` per verdict) and a SHA-1 of every verdict in full:
    success, reason, each criterion's verdict and its measured value (``repr`` of the float)."""
    flags = "".join("1" if v.success else "0" for v in verdicts)
    text = json.dumps(
        [[v.primitive, v.success, v.reason, v.criteria, {k: repr(m) for k, m in v.measures.items()}] for v in verdicts]
    )
    return flags, hashlib.sha1(text.encode()).hexdigest()


@pytest.fixture(scope="module")
def datasets():
    return {
        "with_images": generate_dataset(WITH_IMAGES, seed=0, workers=1, progress=False),
        "no_images": generate_dataset(NO_IMAGES, seed=0, workers=1, progress=False),
    }


def array_digests(ds) -> dict:
    return {
        "motor": sha1(np.asarray(ds.motor, dtype=np.float32)),
        "labels": sha1(np.asarray(ds.labels)),
        "params": sha1(np.asarray(ds.params, dtype=np.float32)),
        "images": sha1(None if ds.images is None else np.asarray(ds.images)),
    }


def script_digest() -> str:
    """Every primitive's scripted path (TCP, fingers, contact phase, push direction) at three blocks."""
    scene = Scene()
    h = hashlib.sha1()
    for name in PRIMITIVES:
        for x, y, size in ((0.42, -0.15, 0.035), (0.60, 0.15, 0.065), (0.51, 0.03, 0.05)):
            s = script_motion(scene, name, x, y, size, 61)
            h.update(np.ascontiguousarray(s.tcp).tobytes() + np.ascontiguousarray(s.fingers).tobytes())
            h.update(
                repr((s.primitive, s.block_xy.tolist(), s.size, s.contact_start, s.push_axis, s.push_sign)).encode()
            )
    return h.hexdigest()


def judged(ds):
    """Verdicts on the recorded motions: each under its own label, and all under all seven."""
    motor = np.asarray(ds.motor)
    own = [evaluate(int(label), q, p) for label, q, p in zip(ds.labels, motor, ds.params)]
    confusion = [evaluate(judge, q, p) for q, p in zip(motor, ds.params) for judge in PRIMITIVES]
    return own, confusion


def perturbed_verdicts(ds):
    """Verdicts on motions moved so that some fail: a joint offset, noise, a time shift, reversal."""
    motor = np.asarray(ds.motor, dtype=float)
    rng = np.random.default_rng(0)
    out = []
    for label, q, p in zip(ds.labels, motor, ds.params):
        variants = [
            q + np.r_[0.0, 0.004, 0, 0, 0, 0, 0, 0, 0],  # shoulder by 4 mrad: about 2 mm at the tip
            q + np.r_[0.04, 0, 0, 0, 0, 0, 0, 0, 0],  # base by 40 mrad: about 2 cm sideways
            q + rng.normal(scale=0.003, size=q.shape) * np.r_[np.ones(7), 0, 0],
            np.concatenate([q[:1].repeat(3, axis=0), q[:-3]]),  # three steps late
            q[::-1],
        ]
        out += [evaluate(int(label), v, p) for v in variants]
    return out


def test_judge_version_is_pinned():
    assert JUDGE_VERSION == 2


@pytest.mark.slow
def test_generated_arrays_are_pinned(datasets):
    pinned, _ = pinned_for_this_cpu(BY_CPU, "generated arrays")
    assert {name: array_digests(ds) for name, ds in datasets.items()} == pinned


def test_scripted_paths_are_pinned():
    _, scripts = pinned_for_this_cpu(BY_CPU, "scripted paths")
    assert script_digest() == scripts


def test_judge_verdicts_are_pinned(datasets):
    ds = datasets["with_images"]
    own, confusion = judged(ds)
    assert all(v.success for v in own)
    assert digest(own) == PINNED_VERDICTS["own"]
    assert digest(confusion) == PINNED_VERDICTS["confusion"]
    assert digest(perturbed_verdicts(ds)) == PINNED_VERDICTS["perturbed"]


def test_no_images_labels_are_the_primitive_index(datasets):
    ds = datasets["no_images"]
    assert ds.images is None
    np.testing.assert_array_equal(ds.labels, np.repeat([PRIMITIVES.index(p) for p in NO_IMAGES.primitives], 2))
    assert dataclasses.replace(NO_IMAGES).n_samples == len(ds)
