"""The data side of docs/real.md's explanation: how many dimensions each data set really uses.

For each data file (``primspace import`` output), scaled as the runs scale it (each joint to
[-1, 1] over the whole file, :func:`primspace.experiments.runs.experiment_scaler`) and
flattened to ``T x J`` values, it prints the mean norm of a scaled motion ``‖m‖``, the
principal components that hold 90 % and 99 % of the variance (the data's effective
dimension, against q), the share of the variance in the top q components (what PCA's q
codes keep), and for the projection ``P`` of seeds 0, 1, 2 (as the runs draw it) the mean
``‖P m‖`` and the centred projected codes' largest over smallest singular value. Not a test;
seconds on one core::

    python benchmarks/real_data_spectrum.py lasa.h5 gunpoint.h5 basicmotions.h5 watch.h5 --q 8
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def spectrum(path: Path, q: int, seeds=(0, 1, 2)) -> dict:
    """The numbers of one data file (module docstring)."""
    from primspace.data import MotionDataset
    from primspace.experiments.runs import experiment_scaler
    from primspace.model.latent import LatentInitializer

    data = MotionDataset.load(path)
    scaled = np.asarray(experiment_scaler(data).transform(data.motor), dtype=np.float64)
    x = scaled.reshape(len(data), -1)
    s = np.linalg.svd(x - x.mean(axis=0), compute_uv=False)
    share = np.cumsum(s**2) / np.sum(s**2)
    conditions, norms = [], []
    for seed in seeds:
        z = LatentInitializer("projection", q, seed).fit_transform(scaled).astype(np.float64)
        sv = np.linalg.svd(z - z.mean(axis=0), compute_uv=False)
        conditions.append(sv[0] / sv[-1])
        norms.append(np.linalg.norm(z, axis=1).mean())
    return {
        "file": path.name,
        "n": len(data),
        "values": x.shape[1],
        "m_norm": float(np.linalg.norm(x, axis=1).mean()),
        "components_90": int(np.searchsorted(share, 0.9) + 1),
        "components_99": int(np.searchsorted(share, 0.99) + 1),
        "top_q_share": float(share[min(q, share.size) - 1]),
        "pm_norm": float(np.mean(norms)),
        "pm_condition": float(np.mean(conditions)),
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("files", nargs="+", type=Path, help="data files (primspace import output)")
    parser.add_argument("--q", type=int, default=8, help="the latent size (default 8, the real preset's)")
    args = parser.parse_args(argv)
    print(f"| data | n | T·J | ‖m‖ | components for 90 % / 99 % | top {args.q} share | ‖P m‖ | σ1/σq of P m |")
    print("|---|---|---|---|---|---|---|---|")
    for path in args.files:
        r = spectrum(path, args.q)
        print(
            f"| {r['file']} | {r['n']} | {r['values']} | {r['m_norm']:.2g} | {r['components_90']} / "
            f"{r['components_99']} | {r['top_q_share']:.2f} | {r['pm_norm']:.2g} | {r['pm_condition']:.2g} |"
        )


if __name__ == "__main__":
    main()
