"""seglearn's bundled smartwatch recordings as an ``.npz`` archive that ``primspace import`` reads.

seglearn (``pip install -e '.[eval]'``) ships ``data/watch_dataset.npy``: 140 recordings of
7 shoulder physiotherapy exercises (PEN, ABD, FEL, IR, ER, TRAP, ROW) by 10 subjects, a
3-axis accelerometer and a 3-axis gyroscope (``ax, ay, az, wx, wy, wz``) at 50 Hz,
1000-2500 steps each. It is a pickled dict, which ``primspace import`` never unpickles; this
script (reading the installed package's own file, nothing downloaded) writes its
recordings as ``arr_0, arr_1, ...`` with ``labels`` (the exercise names), ``joint_names``
and ``dt`` = 0.02 s, and the subject and side as ``params``::

    python benchmarks/watch_npz.py watch.npz
    primspace import watch.npz --format npz --length 50 --out watch.h5
"""

from __future__ import annotations

import argparse
import importlib.util
from pathlib import Path

import numpy as np

#: seglearn's recordings are sampled at 50 Hz (its documentation of the watch data set).
WATCH_DT = 0.02


def watch_arrays() -> dict[str, np.ndarray]:
    """The arrays of the archive (module docstring)."""
    spec = importlib.util.find_spec("seglearn")  # the data file only; the package is not imported
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("seglearn is not installed: pip install -e '.[eval]'")
    path = Path(spec.submodule_search_locations[0]) / "data" / "watch_dataset.npy"
    data = np.load(path, allow_pickle=True).item()  # the installed package's own file
    names = [str(s) for s in data["y_labels"]]
    arrays = {f"arr_{i}": np.asarray(x, dtype=np.float64) for i, x in enumerate(data["X"])}
    arrays["labels"] = np.array([names[int(y)] for y in data["y"]])
    arrays["label_names"] = np.array(names)
    arrays["joint_names"] = np.array([str(s) for s in data["X_labels"]])
    arrays["params"] = np.stack([np.asarray(data["subject"], float), np.asarray(data["side"], float)], axis=1)
    arrays["param_names"] = np.array(["subject", "side"])
    arrays["dt"] = np.array(WATCH_DT)
    return arrays


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("out", type=Path, help="the .npz archive to write")
    args = parser.parse_args(argv)
    if args.out.exists():
        raise SystemExit(f"{args.out}: exists; remove it first")
    np.savez(args.out, **watch_arrays())
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
