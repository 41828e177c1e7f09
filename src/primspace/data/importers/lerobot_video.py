"""Frames of a LeRobot episode, by timestamp: from a video (PyAV) or from images in its table.

The timestamp rule (LeRobot's, with the tolerance this importer uses): the frame of table
row ``r`` is the decoded frame whose presentation time (``pts * time_base``) is nearest to

    wanted_r = from_timestamp + timestamp_r

(``from_timestamp`` is the episode's start in a v3.0 video file that holds several
episodes, 0 for a v2.x video of one episode; ``timestamp_r`` the row's time within its
episode, else ``frame_index / fps``). Only frames of the episode count: in v3.0 those whose
time lies in ``[from_timestamp, to_timestamp)``. The nearest frame must lie within half a
frame period, ``0.5 / fps``, of the time wanted, else the import stops naming the file, the
camera, the episode, the row and both times. So a video with a frame more than its table
has rows imports (every row finds its frame), and so do timestamps that jitter by less
than half a period; a video that ends early, or timestamps that run past the episode's
frames, are refused.

Decoding starts at the key frame before the first time wanted (a seek), and is redone from
the start of the file when the seek lands after that time; it stops after the last time
wanted. Only the frames picked are converted to RGB.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from primspace.data.importers.common import printable
from primspace.utils.errors import DataError, first_line

__all__ = ["video_frames", "table_images"]

# a frame this close to the edge of an episode's span still belongs to it (float rounding of the times)
_EDGE = 1e-4


def video_frames(
    av, file: Path, key: str, episode, times: np.ndarray, rows: np.ndarray, fps: float, sample: int
) -> np.ndarray:
    """The frames of table rows ``rows`` of ``episode``, from the video ``file`` of camera ``key``.

    Parameters
    ----------
    av : module
        PyAV.
    episode : Episode
        Its ``start`` (``from_timestamp``), ``end`` (``to_timestamp`` or None) and ``index``.
    times : (n_rows,) float
        Each row's time within the episode (``timestamp``), in seconds.
    rows : (k,) int
        The rows wanted, sorted.
    sample : int
        The episode's place among those imported (for messages).

    Raises
    ------
    DataError
        No such file, not a video, or a row whose nearest frame is more than half a
        frame period away from its time.
    """

    def fail(message: str) -> DataError:
        return DataError(f"episode {episode.index}: {message}", path=file, field=printable(key), index=sample)

    if not file.is_file():
        raise fail("no such file (episode video)")
    wanted = episode.start + times[rows]
    tol = 0.5 / fps
    span = (episode.start - min(_EDGE, tol / 2), np.inf if episode.end is None else episode.end - min(_EDGE, tol / 2))
    order = np.argsort(wanted, kind="stable")  # times that do not increase are still each matched
    try:
        picked, found = _nearest(av, file, wanted[order], span, seek=max(span[0], float(wanted[order[0]]) - tol))
    except (av.error.FFmpegError, OSError, ValueError, TypeError, ZeroDivisionError) as exc:
        raise fail(f"cannot be decoded ({first_line(exc)})") from None
    back = np.argsort(order)
    picked, found = [picked[k] for k in back], found[back]
    if np.isnan(found).all():
        inside = (
            ""
            if episode.end is None
            else f" between from_timestamp {episode.start:g} s and to_timestamp {episode.end:g} s"
        )
        raise fail(f"the video holds no frames{inside}")
    far = np.flatnonzero(~(np.abs(found - wanted) <= tol))
    if far.size:
        j = int(far[0])
        time = (
            f"from_timestamp {episode.start:g} s + timestamp {times[rows[j]]:g} s = {wanted[j]:g} s"
            if episode.start
            else f"timestamp {wanted[j]:g} s"
        )
        raise fail(
            f"row {int(rows[j])}: the frame at {time} is wanted; the nearest frame of the episode is at "
            f"{found[j]:g} s, {abs(found[j] - wanted[j]):.3g} s away, more than half a frame period "
            f"({tol:g} s at {fps:g} fps)"
        )
    if len({a.shape for a in picked}) > 1:
        raise fail("frames of different sizes in one episode")
    return np.stack(picked)


class _Decoded:
    """A decoded frame, its time, and its RGB array once asked for."""

    def __init__(self, time: float, frame) -> None:
        self.time, self.frame, self._array = time, frame, None

    def array(self) -> np.ndarray:
        if self._array is None:
            self._array = self.frame.to_ndarray(format="rgb24")
        return self._array


def _nearest(av, file: Path, wanted: np.ndarray, span: tuple[float, float], seek: float):
    """For each time ``wanted`` (sorted), the decoded frame with time in ``span`` nearest to it
    and that frame's time (NaN: no frame): decoding from a seek to ``seek`` when that is exact."""
    if seek > 0:
        result = _scan(av, file, wanted, span, seek)
        if result is not None:
            return result
    return _scan(av, file, wanted, span, None)


def _scan(av, file: Path, wanted: np.ndarray, span: tuple[float, float], seek: float | None):
    """One pass of :func:`_nearest` (a merge of the sorted times wanted with the frames as
    decoded); None when decoding after the seek starts later than ``seek``."""
    n, (low, high) = len(wanted), span
    picked, found = [None] * n, np.full(n, np.nan)
    j, before = 0, None
    with av.open(str(file)) as container:
        if not container.streams.video:
            raise ValueError("the file holds no video stream")
        stream = container.streams.video[0]
        if seek is not None:
            if not stream.time_base:
                return None
            container.seek(int(seek / stream.time_base), stream=stream, backward=True, any_frame=False)
        for frame in container.decode(stream):
            time = frame.time
            if time is None:
                continue
            if seek is not None:
                if time > seek:  # the seek skipped frames that may be wanted
                    return None
                seek = None
            if time < low:
                continue
            if time >= high:
                break
            now = _Decoded(float(time), frame)
            while j < n and wanted[j] <= now.time:  # the frame before and this one bracket wanted[j]
                near = before if before is not None and wanted[j] - before.time <= now.time - wanted[j] else now
                picked[j], found[j], j = near.array(), near.time, j + 1
            if j == n:
                break
            before = now
        for k in range(j, n if before is not None else j):  # after the last frame: the last frame
            picked[k], found[k] = before.array(), before.time
    return picked, found


def table_images(table, key: str, wanted: np.ndarray, file: Path, episode: int, sample: int) -> np.ndarray:
    """Frames of an ``image`` feature: encoded bytes (PNG, JPEG) in the episode's rows, decoded with Pillow."""
    from PIL import Image, UnidentifiedImageError

    def fail(message: str) -> DataError:
        return DataError(f"episode {episode}: {message}", path=file, field=printable(key), index=sample)

    cells = table.column(key).take(np.asarray(wanted, dtype=np.int64)).to_pylist()
    out = []
    for w, cell in zip(wanted, cells):
        data = cell.get("bytes") if isinstance(cell, dict) else cell
        try:
            with Image.open(io.BytesIO(data)) as image:
                out.append(np.asarray(image.convert("RGB")))
        except (TypeError, ValueError, OSError, UnidentifiedImageError, Image.DecompressionBombError) as exc:
            raise fail(f"row {int(w)}: not an encoded image ({first_line(exc)})") from None
    if len({a.shape for a in out}) > 1:
        raise fail("frames of different sizes in one episode")
    return np.stack(out)
