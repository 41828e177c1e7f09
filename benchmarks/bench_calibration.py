"""What the calibrated start costs: fitting a run's calibration map at the end of ``fit``.

A ridge regression with intercept (towards the identity, α by leave-one-out over 19
values) plus its 5-fold held-out R² (one more ridge per fold), for the code tables of
LASA (52 x 8), the paper preset (343 x 40) and a larger training part (2000 x 40). The
first call also imports scikit-learn (timed apart). Prints seconds per fit; for scale,
one fit epoch of the paper preset takes 37 s on 2 cores (``bench_train.py``), so the map
costs well under one epoch of the 800.

    python benchmarks/bench_calibration.py
"""

from __future__ import annotations

import time

import numpy as np


def main() -> None:
    t0 = time.perf_counter()
    import sklearn.linear_model  # noqa: F401  (the import, timed on its own)

    print(f"import scikit-learn: {time.perf_counter() - t0:.2f} s")
    from primspace.model.calibration import CodeCalibration

    rng = np.random.default_rng(0)
    for n, q in ((52, 8), (343, 40), (2000, 40)):
        x = rng.normal(size=(n, q))
        y = x + 0.2 * x @ rng.normal(size=(q, q)) / np.sqrt(q) + 0.05 * rng.normal(size=(n, q))
        times = []
        for _ in range(3):
            t = time.perf_counter()
            cal = CodeCalibration(q).fit(x, y)
            times.append(time.perf_counter() - t)
        print(f"n = {n:5d}, q = {q:3d}: {min(times):.3f} s (best of 3), held-out R^2 {cal.heldout_r2_:.4f}")


if __name__ == "__main__":
    main()
