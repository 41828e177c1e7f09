"""Resampling sequences to a common length by zero padding in the frequency domain.

The paper (Experimental Results, *Motion Capture Data*) aligns demonstrations of
different lengths to T steps by taking the DFT of each joint's sequence, inserting
``T - T0`` zeros between its positive and negative frequencies, and transforming back:

    f = F(m_{1:T0});   f~ = [f_{1:T0/2}, 0, ..., 0, f_{T0/2:T0}];   m~ = F^{-1}(f~)

Taken literally this treats a trajectory as one period of a periodic signal: a motion
that ends elsewhere than it starts has a jump at the wrap-around, and the band-limited
interpolant rings at both ends (endpoints off by ~46% of the range, measured on a
ramp). primspace removes the straight line from the first to the last sample, resamples
the residual, which is zero at both ends and so continues periodically without a jump,
and adds the line back. Sample ``k`` of an input of length ``T0`` is taken to lie at
time ``k / (T0 - 1)`` of the motion, output sample ``j`` at ``j / (T - 1)``: both ends
are kept exactly.

What is exact (to float precision):

* a linear trend, and the first and last values of any sequence;
* a band-limited signal plus a linear trend, when the signal's period is the duration
  of the motion and its bandwidth is below half of ``min(T0, T) - 1``;
* with ``periodic=True`` (the paper's formula as written, no line removal, samples at
  ``k / T0`` of one period): any band-limited periodic signal.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from primspace.utils.errors import DataError

__all__ = ["resample"]


def resample(sequences, length: int, *, periodic: bool = False) -> np.ndarray:
    """Resample one sequence or many to ``length`` time steps (paper, Motion Capture Data).

    Parameters
    ----------
    sequences : array-like or sequence of array-like
        One of: a 1-D signal ``(T0,)``; one sequence ``(T0, J)``; a batch ``(n, T0, J)``;
        or a list of ``n`` sequences ``(T_i, J)`` of different lengths.
    length : int
        T, the number of output steps (at least 2). Shorter than the input downsamples
        (the spectrum is truncated: an ideal low-pass).
    periodic : bool, default False
        Treat each sequence as one period of a periodic signal and apply the paper's
        zero padding as written. The default removes the first-to-last line first so
        both endpoints are kept (see the module docstring).

    Returns
    -------
    ndarray of float64
        ``(T,)``, ``(T, J)`` or ``(n, T, J)``, matching the input.

    Raises
    ------
    DataError
        A sequence shorter than 2 steps, a bad rank, NaN/inf, or joint counts that disagree;
        the message names the sample index.
    """
    if not isinstance(length, (int, np.integer)) or length < 2:
        raise DataError(f"the target length must be an integer >= 2, got {length!r}", field="length")
    length = int(length)
    if isinstance(sequences, np.ndarray) and sequences.dtype != object:
        arr = sequences
        if arr.ndim == 1:
            return _resample_batch(arr[None, :, None], length, periodic)[0, :, 0]
        if arr.ndim == 2:
            return _resample_batch(arr[None], length, periodic)[0]
        if arr.ndim == 3:
            return _resample_batch(arr, length, periodic)
        raise DataError(f"expected a (T0,), (T0, J) or (n, T0, J) array, got shape {arr.shape}", field="motor")
    return _resample_list(sequences, length, periodic)


def _resample_list(seqs: Sequence, length: int, periodic: bool) -> np.ndarray:
    seqs = list(seqs)
    if not seqs:
        raise DataError("no sequences to resample", field="motor")
    n_joints = None
    out = None
    for i, seq in enumerate(seqs):
        a = np.asarray(seq)
        if a.dtype.kind not in "fiu":
            raise DataError(f"must be numbers, got {a.dtype}", field="motor", index=i)
        if a.ndim == 1:
            a = a[:, None]
        if a.ndim != 2:
            raise DataError(f"a sequence must be (T_i, J), got shape {a.shape}", field="motor", index=i)
        if n_joints is None:
            n_joints = a.shape[1]
            out = np.empty((len(seqs), length, n_joints))
        elif a.shape[1] != n_joints:
            raise DataError(f"has {a.shape[1]} joints, the first sequence has {n_joints}", field="motor", index=i)
        try:
            out[i] = _resample_batch(a[None], length, periodic)[0]
        except DataError as exc:  # the batch of one says sample 0: it is sample i
            raise DataError(exc.reason, field=exc.field, index=i) from None
    return out


def _resample_batch(x: np.ndarray, length: int, periodic: bool) -> np.ndarray:
    """Resample a ``(n, T0, J)`` batch along axis 1."""
    # imported here: scipy.signal costs ~0.9 s per process, and every data-layer user
    # (simulation workers among them) would pay it
    from scipy.signal import resample as _fourier_resample

    if x.dtype.kind not in "fiu":
        raise DataError(f"must be numbers, got {x.dtype}", field="motor")
    if x.dtype.kind == "f" and x.dtype.itemsize > 8:  # long double: name a value float64 cannot hold
        with np.errstate(invalid="ignore", over="ignore"):
            big = np.isfinite(x) & (np.abs(x) > np.finfo(np.float64).max)
        if big.any():
            bad = np.argwhere(big)[0]
            value = np.format_float_scientific(x[tuple(bad)], precision=6, trim="-")
            raise DataError(
                f"value {value} exceeds the float64 range (step {int(bad[1])}, joint {int(bad[2])})",
                field="motor",
                index=int(bad[0]),
            )
    x = np.asarray(x, dtype=np.float64)
    n, t0, _ = x.shape
    if t0 < 2:
        raise DataError(f"a sequence of length {t0} cannot be resampled (needs at least 2 steps)", field="motor")
    finite = np.isfinite(x)
    if not finite.all():
        bad = np.argwhere(~finite)[0]
        raise DataError(
            f"contains NaN or inf (step {int(bad[1])}, joint {int(bad[2])})", field="motor", index=int(bad[0])
        )
    if periodic:
        return _fourier_resample(x, length, axis=1)
    if t0 == length:
        return x.copy()
    first, last = x[:, :1, :], x[:, -1:, :]
    ramp_in = np.linspace(0.0, 1.0, t0)[None, :, None]
    ramp_out = np.linspace(0.0, 1.0, length)[None, :, None]
    residual = x - (first + (last - first) * ramp_in)
    # The residual is zero at both ends, so samples 0..T0-2 are one full period of a
    # continuous periodic signal: resample that period to T-1 samples and close it.
    period = _fourier_resample(residual[:, :-1, :], length - 1, axis=1)
    # Upsampling interpolates through sample 0 (already zero); downsampling low-passes
    # it, so shift by the new start value to keep the ends exact.
    period -= period[:, :1, :]
    out = np.concatenate([period, np.zeros_like(period[:, :1, :])], axis=1)
    return out + first + (last - first) * ramp_out
