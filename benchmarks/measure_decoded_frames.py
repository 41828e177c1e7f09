"""Does the image head draw the block? The decoded first frame of a run trained with frames (issue 40).

A measurement, not a test. For a run whose model has an image head, on its fitted samples
(the data file's first frames, the run's fitted codes), torch at one thread:

a. **the decoded first frame against the real one.** Frame 0 of each fitted code
   (``run.model(z, frame_steps=0)``, rounded to uint8 as ``reconstruct`` does) and the real
   frame 0, both read by :class:`~primspace.act.frame_features.ColourBlob` (the block's
   colour: mass, column, row): is the block's colour in the decoded frames (mass), and how
   well the decoded centroid tracks the real one (correlation per axis, mean absolute error
   in pixels, against always answering the mean real centroid). Also the block's red excess
   (R - max(G, B), the blob's measure before its threshold) at its brightest inside a 7 x 7
   window around the real centroid, and the mean absolute pixel error inside that window,
   of the decoded frame and of the mean real first frame; the share of the decoded frame's
   squared error (what a pixel loss on frame 0 sums) that lies inside the window; and for
   each real frame 0 the fitted code whose decoded frame 0 is nearest in squared pixel error
   (its own code how often, how far its block is).
b. **how much frame 0 moves along the code prior's directions.** The fitted codes of one
   primitive (labels from the data file), their principal directions: each code moved by
   +-1 standard deviation along each of the top 5, frame 0 decoded, and the mean absolute
   pixel change (0-255) against the unmoved code's frame, over the whole frame and inside
   the 7 x 7 window around that sample's real block centroid. For scale: the change between
   the real first frames of two neighbouring block positions (same size, adjacent cells of
   the preset's grid, any primitive, among the fitted samples; the window around each
   block, averaged), and between the decoded first frames of the same pairs.
c. **the motor head along the same directions**, for contrast: the mean absolute joint
   change (scaled units, and as a fraction of the primitive's spread: the mean absolute
   deviation of its decoded motions from their mean; the image change is given the same
   way, against the spread of the decoded and of the real first frames inside the window).

Usage::

    python benchmarks/measure_decoded_frames.py --run RUN_DIR --data DATA.h5 [--primitive push]
        [--directions 5] [--preset paper] [--json PATH]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

from primspace.utils.files import atomic_write_json

WINDOW = 7  # pixels each side of the block's window: 7 x 7


def _decode(run, codes: np.ndarray, batch: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Frame 0 (n, H, W, 3) uint8 and the motion (n, T, J) scaled of ``codes`` (n, q)."""
    model = run.model
    model.eval()
    frames, motor = [], []
    with torch.no_grad():
        for start in range(0, len(codes), batch):
            z = torch.from_numpy(np.ascontiguousarray(codes[start : start + batch], dtype=np.float32))
            steps = torch.zeros((len(z), 1), dtype=torch.long)
            out = model(z, images=True, frame_steps=steps)
            frames.append(out.images[:, 0].float().mul(255).round_().clamp_(0, 255).to(torch.uint8).numpy())
            motor.append(out.motor.float().numpy())
    return np.concatenate(frames), np.concatenate(motor)


def _moments(blob, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mass (n,) and centroid [u, v] (n, 2), NaN where the mass is 0 (no stand-in)."""
    w = blob.weights(frames)
    rows, cols = np.indices(w.shape[1:], dtype=np.float64)
    mass = w.sum(axis=(1, 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        centroid = np.stack([(w * cols).sum(axis=(1, 2)) / mass, (w * rows).sum(axis=(1, 2)) / mass], axis=1)
    return mass, np.where(mass[:, None] > 0, centroid, np.nan)


def _window(centroid: np.ndarray, shape: tuple[int, int]) -> tuple[slice, slice]:
    """The 7 x 7 window (rows, cols) around ``centroid`` [u, v], kept inside the frame."""
    h, w = shape
    half = WINDOW // 2
    r = int(np.clip(round(float(centroid[1])), half, h - 1 - half))
    c = int(np.clip(round(float(centroid[0])), half, w - 1 - half))
    return slice(r - half, r + half + 1), slice(c - half, c + half + 1)


def _excess(frames: np.ndarray) -> np.ndarray:
    """R - max(G, B) per pixel, (n, H, W) float."""
    f = frames.astype(np.float64)
    return f[..., 0] - np.maximum(f[..., 1], f[..., 2])


def _abs(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(a.astype(np.float64) - b.astype(np.float64))


def _cells(params: np.ndarray, preset: str) -> np.ndarray:
    """Each sample's grid cell (ix, iy) of the preset's block grid."""
    from primspace.sim.config import PRESETS

    config = PRESETS[preset]
    xs, ys = np.asarray(config.block_x), np.asarray(config.block_y)
    ix = np.abs(params[:, 0:1] - xs[None]).argmin(axis=1)
    iy = np.abs(params[:, 1:2] - ys[None]).argmin(axis=1)
    return np.stack([ix, iy], axis=1)


def _neighbours(params: np.ndarray, preset: str) -> list[tuple[int, int]]:
    """Pairs of samples with the same block size in adjacent grid cells."""
    cells = _cells(params, preset)
    sizes = np.round(params[:, 2], 5)
    pairs = []
    for i in range(len(params)):
        for j in range(i + 1, len(params)):
            if sizes[i] == sizes[j] and np.abs(cells[i] - cells[j]).sum() == 1:
                pairs.append((i, j))
    return pairs


def _pair_change(frames: np.ndarray, centroids: np.ndarray, pairs) -> dict:
    """Mean absolute pixel change between the frames of each pair: whole frame, and inside the
    window around each block (the two windows averaged)."""
    shape = frames.shape[1:3]
    whole, inside = [], []
    for i, j in pairs:
        diff = _abs(frames[i], frames[j])
        whole.append(diff.mean())
        inside.append(np.mean([diff[_window(centroids[k], shape)].mean() for k in (i, j)]))
    return {"pairs": len(pairs), "whole": float(np.mean(whole)), "window": float(np.mean(inside))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, required=True, help="a trained run directory with an image head")
    parser.add_argument("--data", type=Path, required=True, help="the data file it was fitted on, with frames")
    parser.add_argument("--primitive", default="push", help="the primitive whose codes give the directions")
    parser.add_argument("--directions", type=int, default=5, help="principal directions moved along")
    parser.add_argument("--preset", default="paper", help="the preset whose block grid defines neighbours")
    parser.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = parser.parse_args()
    torch.set_num_threads(1)

    from primspace.act.frame_features import ColourBlob
    from primspace.data import MotionDataset
    from primspace.train import load_run
    from primspace.train.starts import fitted_samples
    from primspace.utils.errors import UserError

    try:
        run = load_run(args.run)
        fitted = fitted_samples(run, MotionDataset.load(args.data))
    except UserError as exc:
        sys.exit(f"measure_decoded_frames: {exc}")
    if run.model.image_head is None:
        sys.exit(f"measure_decoded_frames: the run {args.run} has no image head")
    if not fitted.has_images:
        sys.exit(f"measure_decoded_frames: the run's fitted data ({args.data}) has no camera frames")
    real = np.asarray(fitted.load_images().images[:, 0])
    codes = np.asarray(run.latents, dtype=np.float32)
    shape = real.shape[1:3]
    last_epoch = run.history[-1] if run.history else {}
    print(
        f"run {args.run}: q = {codes.shape[1]}, {len(codes)} fitted codes, frames {shape}, "
        f"epoch {last_epoch.get('epoch')} (vision loss {last_epoch.get('vision', float('nan')):.3g})"
    )
    figures: dict = {
        "setting": {
            "run": str(args.run),
            "data": str(args.data),
            "q": int(codes.shape[1]),
            "fitted": int(len(codes)),
            "epoch": last_epoch.get("epoch"),
            "vision_loss": last_epoch.get("vision"),
            "window": WINDOW,
        }
    }

    # (a) the decoded first frame against the real one
    decoded, motor = _decode(run, codes)
    blob = ColourBlob().fit(real)
    mass_r, cent_r = _moments(blob, real)
    mass_d, cent_d = _moments(blob, decoded)
    seen = mass_d > 0
    mean_frame = real.astype(np.float64).mean(axis=0)
    excess_r, excess_d, excess_mean = _excess(real), _excess(decoded), _excess(mean_frame[None])[0]
    peak_r, peak_d, peak_mean, err_d, err_mean, share = [], [], [], [], [], []
    for n in range(len(real)):
        win = _window(cent_r[n], shape)
        peak_r.append(excess_r[n][win].max())
        peak_d.append(excess_d[n][win].max())
        peak_mean.append(excess_mean[win].max())
        err_d.append(_abs(decoded[n][win], real[n][win]).mean())
        err_mean.append(_abs(mean_frame[win], real[n][win]).mean())
        squared = _abs(decoded[n], real[n]) ** 2
        share.append(squared[win].sum() / max(squared.sum(), 1e-12))
    a = {
        "real_mass_mean": float(mass_r.mean()),
        "real_with_block": float(np.mean(mass_r > 0)),
        "decoded_mass_mean": float(mass_d.mean()),
        "decoded_mass_median": float(np.median(mass_d)),
        "decoded_with_colour": float(np.mean(seen)),
        "decoded_with_colour_ge_1px": float(np.mean(mass_d >= 1.0)),
        "mass_correlation": float(np.corrcoef(mass_r, mass_d)[0, 1]) if mass_d.std() > 0 else None,
        "peak_excess_real": float(np.mean(peak_r)),
        "peak_excess_decoded": float(np.mean(peak_d)),
        "peak_excess_mean_frame": float(np.mean(peak_mean)),
        "peak_excess_decoded_whole_frame_max": float(excess_d.max()),
        "window_error_decoded": float(np.mean(err_d)),
        "window_error_mean_frame": float(np.mean(err_mean)),
        "whole_error_decoded": float(_abs(decoded, real).mean()),
        "whole_error_mean_frame": float(_abs(mean_frame[None], real).mean()),
        "window_share_of_squared_error": float(np.mean(share)),
        "window_share_of_pixels": WINDOW * WINDOW / float(shape[0] * shape[1]),
    }
    flat_r = real.reshape(len(real), -1).astype(np.float64)
    flat_d = decoded.reshape(len(decoded), -1).astype(np.float64)
    distance = (flat_r**2).sum(1)[:, None] - 2 * flat_r @ flat_d.T + (flat_d**2).sum(1)[None]
    nearest = distance.argmin(axis=1)
    a["retrieval"] = {
        "own_code": float(np.mean(nearest == np.arange(len(real)))),
        "centroid_error_px": float(np.linalg.norm(cent_r[nearest] - cent_r, axis=1).mean()),
        "size_same": float(np.mean(np.isclose(fitted.params[nearest, 2], fitted.params[:, 2]))),
        "centroid_error_px_random": float(
            np.linalg.norm(cent_r[np.random.default_rng(0).permutation(len(real))] - cent_r, axis=1).mean()
        ),
    }
    if seen.sum() >= 3:
        both = seen & (mass_r > 0)
        err = np.abs(cent_d[both] - cent_r[both])
        base = np.abs(cent_r[both] - np.nanmean(cent_r, axis=0)[None])
        a["centroid"] = {
            "frames": int(both.sum()),
            "corr_u": float(np.corrcoef(cent_d[both, 0], cent_r[both, 0])[0, 1]),
            "corr_v": float(np.corrcoef(cent_d[both, 1], cent_r[both, 1])[0, 1]),
            "mae_u_px": float(err[:, 0].mean()),
            "mae_v_px": float(err[:, 1].mean()),
            "mae_u_px_mean_answer": float(base[:, 0].mean()),
            "mae_v_px_mean_answer": float(base[:, 1].mean()),
        }
    else:
        a["centroid"] = None
    figures["first_frame"] = a
    print("\n(a) decoded frame 0 against the real frame 0 (ColourBlob of the block's colour)")
    print(
        f"  mass: real {a['real_mass_mean']:.2f} px (block seen in {100 * a['real_with_block']:.0f} %), decoded "
        f"mean {a['decoded_mass_mean']:.3f} median {a['decoded_mass_median']:.3f} px; decoded frames with the "
        f"colour: {100 * a['decoded_with_colour']:.0f} % (>= 1 px: {100 * a['decoded_with_colour_ge_1px']:.0f} %); "
        f"mass correlation {a['mass_correlation']}"
    )
    if a["centroid"] is not None:
        c = a["centroid"]
        print(
            f"  centroid over {c['frames']} frames: corr u {c['corr_u']:.3f} v {c['corr_v']:.3f}; MAE u "
            f"{c['mae_u_px']:.2f} v {c['mae_v_px']:.2f} px (the mean real centroid: u {c['mae_u_px_mean_answer']:.2f} "
            f"v {c['mae_v_px_mean_answer']:.2f} px)"
        )
    else:
        print("  centroid: too few decoded frames have the colour to compare")
    r = a["retrieval"]
    print(
        f"  the code whose decoded frame 0 is nearest the real frame 0 in pixels: its own {100 * r['own_code']:.0f} %, "
        f"block centroid off by {r['centroid_error_px']:.2f} px (a random code: {r['centroid_error_px_random']:.2f}), "
        f"same block size {100 * r['size_same']:.0f} %"
    )
    print(
        f"  red excess R - max(G, B) at its peak in the block's 7x7 window: real {a['peak_excess_real']:.1f}, "
        f"decoded {a['peak_excess_decoded']:.1f}, mean real frame {a['peak_excess_mean_frame']:.1f} "
        f"(blob threshold 50; decoded peak anywhere {a['peak_excess_decoded_whole_frame_max']:.1f})"
    )
    print(
        f"  mean abs pixel error (0-255) in the window: decoded {a['window_error_decoded']:.2f}, mean real frame "
        f"{a['window_error_mean_frame']:.2f}; whole frame: decoded {a['whole_error_decoded']:.2f}, mean real frame "
        f"{a['whole_error_mean_frame']:.2f}"
    )
    print(
        f"  share of the decoded frame's squared error (a pixel loss) inside the window: "
        f"{100 * a['window_share_of_squared_error']:.1f} % ({100 * a['window_share_of_pixels']:.1f} % of the pixels)"
    )

    # (b), (c) along the principal directions of one primitive's codes
    names = list(fitted.label_names) if fitted.label_names is not None else []
    label = names.index(args.primitive) if args.primitive in names else int(args.primitive)
    rows = np.flatnonzero(fitted.labels == label)
    if len(rows) < 2:
        sys.exit(f"measure_decoded_frames: primitive {args.primitive} has {len(rows)} fitted codes: at least 2")
    z = codes[rows].astype(np.float64)
    _, s, vt = np.linalg.svd(z - z.mean(axis=0), full_matrices=False)
    std = s / np.sqrt(len(rows) - 1)
    top = min(args.directions, len(std))
    base_frames, base_motor = decoded[rows], motor[rows]
    spread_motor = float(np.abs(base_motor - base_motor.mean(axis=0)).mean())
    spread_dec = np.mean(
        [_abs(base_frames[n], base_frames.mean(axis=0))[_window(cent_r[i], shape)].mean() for n, i in enumerate(rows)]
    )
    real_k = real[rows]
    spread_real = np.mean(
        [_abs(real_k[n], real_k.mean(axis=0))[_window(cent_r[i], shape)].mean() for n, i in enumerate(rows)]
    )
    directions = []
    for d in range(top):
        whole, inside, joints = [], [], []
        for sign in (1.0, -1.0):
            moved = (z + sign * std[d] * vt[d][None]).astype(np.float32)
            frames_m, motor_m = _decode(run, moved)
            diff = _abs(frames_m, base_frames)
            whole.append(diff.mean())
            inside.append(np.mean([diff[n][_window(cent_r[i], shape)].mean() for n, i in enumerate(rows)]))
            joints.append(np.abs(motor_m - base_motor).mean())
        directions.append(
            {
                "direction": d + 1,
                "std": float(std[d]),
                "explained": float(std[d] ** 2 / np.sum(std**2)),
                "pixels_whole": float(np.mean(whole)),
                "pixels_window": float(np.mean(inside)),
                "joints_scaled": float(np.mean(joints)),
            }
        )
    pairs = _neighbours(np.asarray(fitted.params, dtype=np.float64), args.preset)
    real_pairs = _pair_change(real, cent_r, pairs) if pairs else None
    decoded_pairs = _pair_change(decoded, cent_r, pairs) if pairs else None
    mean_window = float(np.mean([r["pixels_window"] for r in directions]))
    mean_joints = float(np.mean([r["joints_scaled"] for r in directions]))
    figures["directions"] = {
        "primitive": args.primitive,
        "codes": int(len(rows)),
        "rows": directions,
        "mean_pixels_whole": float(np.mean([r["pixels_whole"] for r in directions])),
        "mean_pixels_window": mean_window,
        "mean_joints_scaled": mean_joints,
        "spread_window_decoded": float(spread_dec),
        "spread_window_real": float(spread_real),
        "spread_joints_scaled": spread_motor,
        "neighbours_real": real_pairs,
        "neighbours_decoded": decoded_pairs,
    }
    print(
        f"\n(b, c) {len(rows)} fitted codes of {args.primitive}, each moved +-1 std along the top {top} principal "
        f"directions; mean abs change of decoded frame 0 (0-255) and of the decoded motion (scaled joints)"
    )
    print(f"  {'dir':>3} {'std':>7} {'var %':>6} {'px whole':>9} {'px window':>9} {'joints':>8}")
    for r in directions:
        print(
            f"  {r['direction']:>3} {r['std']:>7.3f} {100 * r['explained']:>6.1f} {r['pixels_whole']:>9.3f} "
            f"{r['pixels_window']:>9.3f} {r['joints_scaled']:>8.4f}"
        )
    print(
        f"  spread of the primitive (mean abs deviation from its mean): frame 0 in the window decoded "
        f"{spread_dec:.2f}, real {spread_real:.2f}; motion {spread_motor:.4f} scaled"
    )
    print(
        f"  a direction's change over that spread: pixels in the window {mean_window / spread_real:.3f} of the real "
        f"spread ({mean_window / spread_dec:.3f} of the decoded); joints {mean_joints / spread_motor:.3f}"
    )
    if real_pairs:
        print(
            f"  neighbouring block positions ({real_pairs['pairs']} pairs, same size, adjacent cells): real frame 0 "
            f"changes {real_pairs['whole']:.3f} whole, {real_pairs['window']:.2f} in the windows; decoded frame 0 of "
            f"the same pairs {decoded_pairs['whole']:.3f} whole, {decoded_pairs['window']:.2f} in the windows"
        )
    if args.json:
        atomic_write_json(args.json, figures)


if __name__ == "__main__":
    main()
