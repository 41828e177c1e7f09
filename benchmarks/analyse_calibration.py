"""Why does the raw projection start lose to zero on real recordings, and what start does not?

Issue 16, item 2. The setting the issue reports: LASA handwriting (26 shapes x 7 human
demonstrations, resampled to 61 steps), 2 demonstrations per shape fit θ and Z (52), the
other 130 are inferred with θ frozen; q = 8, 400 fit + 250 infer epochs, motor only, the
*default* TrainConfig (what ``primspace train`` / ``infer`` use without flags).

It fits a projection run and a zero run, then infers the held-out demonstrations from
several starts with the projection run's weights (raw ``P m``, calibrated ``B P m + c``,
zero, the mean fitted code, the nearest fitted neighbour in ``P m`` space, the mean of the
5 nearest), and zero's own run from zero; per-sample final losses; code norms and
directions before and after the fit; the sensitivity of projection / calibrated / zero to
the latent learning rate and to the inference epochs. Prints a table with ratios, writes
``analysis.json`` and four figures into ``--out``.

    python benchmarks/analyse_calibration.py --out OUT                 # LASA, the issue's setting; ~10 min
    python benchmarks/analyse_calibration.py --data watch.h5 --preset lasa --out OUT   # where projection loses

``--data`` takes any labelled data set (the second command: seglearn's wrist-sensor
recordings of 7 physiotherapy exercises, CHANGELOG.md, 0.5.0, says how to make the file);
``--preset`` trains as an experiment preset does (``lasa``: the tuned optimiser, 800 + 600
epochs, 30 % fitted).

(Not a timing benchmark: it lives here beside the other measurement scripts.)
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

STARTS = ("projection", "calibrated", "zero (same θ)", "mean fitted code", "nearest neighbour", "5 nearest")


def per_sample_loss(run, data) -> np.ndarray:
    """Each sample's motor MSE (scaled to [-1, 1]) of the run's codes."""
    from primspace.train import reconstruct

    motor, _ = reconstruct(run)
    target = data.subset(run.indices).motor
    return ((run.scaler.transform(motor) - run.scaler.transform(target)) ** 2).mean(axis=(1, 2))


def neighbour_starts(pm_train, z_train, pm_new, k: int) -> np.ndarray:
    """Mean fitted code of the ``k`` training samples whose ``P m`` is nearest."""
    d = ((pm_new[:, None, :] - pm_train[None, :, :]) ** 2).sum(-1)
    nearest = np.argsort(d, axis=1)[:, :k]
    return z_train[nearest].mean(axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="Folder for analysis.json and the figures.")
    parser.add_argument("--latent-dim", type=int, default=8)
    parser.add_argument("--fit-epochs", type=int, help="Default: 400, or the preset's.")
    parser.add_argument("--infer-epochs", type=int, help="Default: 250, or the preset's.")
    parser.add_argument(
        "--preset",
        help="Train as this experiment preset does (its optimiser, epochs, train "
        "fraction); default: TrainConfig() as `primspace train` without flags.",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--velocities", action="store_true", help="LASA with vx, vy beside x, y.")
    parser.add_argument("--data", type=Path, help="Another data set (.h5, with labels) instead of LASA.")
    parser.add_argument(
        "--figures-only", action="store_true", help="Redraw the figures from OUT/calibration_analysis.json."
    )
    args = parser.parse_args()
    if args.figures_only:
        result = json.loads((args.out / "calibration_analysis.json").read_text())
        _figures(result, args.out)
        _print(result)
        return

    from primspace.data import import_lasa
    from primspace.experiments.intra import split_indices
    from primspace.model.config import ModelConfig
    from primspace.train import TrainConfig, configure_process, fit, infer

    start_time = time.perf_counter()
    args.out.mkdir(parents=True, exist_ok=True)
    from primspace.data import MotionDataset

    data = MotionDataset.load(args.data) if args.data else import_lasa(length=61, velocities=args.velocities)
    if args.preset:
        from primspace.experiments.presets import resolve_preset

        preset = resolve_preset(args.preset)
        base, fraction = preset.train, preset.train_fraction
        args.fit_epochs = args.fit_epochs or preset.fit_epochs
        args.infer_epochs = args.infer_epochs or preset.infer_epochs
    else:
        base, fraction = TrainConfig(), 0.3
        args.fit_epochs, args.infer_epochs = args.fit_epochs or 400, args.infer_epochs or 250
    train, held = split_indices(data.labels, fraction, args.seed)
    mc = ModelConfig(latent_dim=args.latent_dim)
    tc = replace(base, epochs=args.fit_epochs, seed=args.seed, threads=args.threads)
    configure_process(tc)
    common = dict(model_config=mc, train_config=tc, indices=train, images=False, progress=False)
    runs = {init: fit(data, None, init=init, **common) for init in ("projection", "zero")}
    proj = runs["projection"]
    scaled_new = proj.scaler.transform(data.subset(held).motor)
    pm_new = proj.initializer.transform(scaled_new).astype(np.float64)
    pm_train = proj.initial_latents.astype(np.float64)
    z_train = proj.latents.astype(np.float64)
    given = {
        "mean fitted code": np.repeat(z_train.mean(0, keepdims=True), len(held), 0),
        "nearest neighbour": neighbour_starts(pm_train, z_train, pm_new, 1),
        "5 nearest": neighbour_starts(pm_train, z_train, pm_new, 5),
    }

    def run_from(start: str, epochs: int = args.infer_epochs, **overrides):
        if start in given:
            return infer(
                proj, data, None, epochs=epochs, indices=held, initial_latents=given[start], progress=False, **overrides
            )
        init = {"zero (same θ)": "zero"}.get(start, start)
        return infer(proj, data, None, epochs=epochs, indices=held, init=init, progress=False, **overrides)

    inferred = {s: run_from(s) for s in STARTS}
    inferred["zero (own θ)"] = infer(runs["zero"], data, None, epochs=args.infer_epochs, indices=held, progress=False)
    table = {}
    for name, run in inferred.items():
        losses = per_sample_loss(run, data)
        table[name] = {
            "start": run.history[0]["loss"],
            "final": run.history[-1]["loss"],
            "curve": [h["loss"] for h in run.history],
            "per_sample": losses.tolist(),
        }

    # codes before and after the fit (train part) and after inference (held-out part)
    cal = proj.calibration
    cos = (pm_train * z_train).sum(1) / (np.linalg.norm(pm_train, axis=1) * np.linalg.norm(z_train, axis=1))
    codes = {
        "fit": {
            "movement": cal.movement_,
            "identity_r2": cal.identity_r2_,
            "heldout_r2": cal.heldout_r2_,
            "alpha": cal.alpha_,
            "norm_pm": np.linalg.norm(pm_train, axis=1).tolist(),
            "norm_fitted": np.linalg.norm(z_train, axis=1).tolist(),
            "cos": cos.tolist(),
            "mean_fitted_norm": float(np.linalg.norm(z_train.mean(0))),
            "mean_pm_norm": float(np.linalg.norm(pm_train.mean(0))),
        },
        "fit_losses": {i: r.history[-1]["loss"] for i, r in runs.items()},
        "norm_pm_new": np.linalg.norm(pm_new, axis=1).tolist(),
        "norm_inferred": {
            s: np.linalg.norm(inferred[s].latents, axis=1).tolist()
            for s in ("projection", "calibrated", "zero (same θ)")
        },
    }

    # sensitivity: latent learning rate and inference epochs
    base_lr = tc.latent_lr
    sensitivity = {"latent_lr": {}, "epochs": {}}
    for start in ("projection", "calibrated", "zero (same θ)"):
        sensitivity["latent_lr"][start] = {
            str(f * base_lr): (
                table[start]["final"] if f == 1 else run_from(start, latent_lr=f * base_lr).history[-1]["loss"]
            )
            for f in (0.3, 1, 3)
        }
        sensitivity["epochs"][start] = {
            str(e): (table[start]["final"] if e == args.infer_epochs else run_from(start, epochs=e).history[-1]["loss"])
            for e in (args.infer_epochs // 2, args.infer_epochs, 2 * args.infer_epochs)
        }

    what = str(args.data) if args.data else "LASA, 26 shapes x 7, T = 61" + (", x y vx vy" if args.velocities else "")
    result = {
        "setting": {
            "data": what,
            "n_fit": len(train),
            "n_infer": len(held),
            "latent_dim": args.latent_dim,
            "fit_epochs": args.fit_epochs,
            "infer_epochs": args.infer_epochs,
            "seed": args.seed,
            "preset": args.preset,
            "train_config": tc.to_dict(),
        },
        "starts": table,
        "codes": codes,
        "sensitivity": sensitivity,
        "seconds": round(time.perf_counter() - start_time, 1),
    }
    (args.out / "calibration_analysis.json").write_text(json.dumps(result, indent=1))
    _figures(result, args.out)
    _print(result)


def _print(result: dict) -> None:
    starts = result["starts"]
    ref = starts["projection"]["final"]
    print(f"{'start':<20}{'start loss':>12}{'final loss':>12}{'final / projection':>20}{'median':>10}{'worst 10%':>11}")
    for name, s in starts.items():
        per = np.sort(s["per_sample"])
        print(
            f"{name:<20}{s['start']:>12.4g}{s['final']:>12.4g}{s['final'] / ref:>20.3g}{np.median(per):>10.3g}"
            f"{per[int(0.9 * len(per)) :].mean():>11.3g}"
        )
    c = result["codes"]["fit"]
    print(
        f"fit: movement {c['movement']:.3f}, R^2 of P m {c['identity_r2']:.3f}, held-out R^2 of the map {c['heldout_r2']:.3f}"
    )
    for what, d in result["sensitivity"].items():
        print(
            f"sensitivity to {what}: "
            + "; ".join(f"{s}: " + ", ".join(f"{k} -> {v:.3g}" for k, v in vals.items()) for s, vals in d.items())
        )
    print(f"{result['seconds']:.0f} s")


def _figures(result: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    from primspace.plots import save_figure
    from primspace.plots.base import init_color

    colours = {
        "zero (same θ)": "tab:cyan",
        "zero (own θ)": "tab:blue",
        "mean fitted code": "tab:gray",
        "nearest neighbour": "tab:brown",
        "5 nearest": "tab:pink",
    }
    starts = result["starts"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for name, s in starts.items():
        colour = colours.get(name) or init_color(name)
        axes[0].plot(s["curve"], label=name, color=colour)
        axes[1].plot(np.sort(s["per_sample"]), np.linspace(0, 1, len(s["per_sample"])), label=name, color=colour)
    axes[0].set(
        yscale="log",
        xlabel="inference epoch",
        ylabel="held-out loss (mean)",
        title="Inference from each start (θ of the projection fit)",
    )
    axes[1].set(
        xscale="log",
        xlabel="per-sample final loss",
        ylabel="fraction of held-out samples",
        title="Per-sample final losses (cumulative)",
    )
    axes[0].legend(fontsize=7)
    save_figure(fig, out / "calibration_starts.png", dpi=90)

    c = result["codes"]
    fig, axes = plt.subplots(1, 3, figsize=(12.5, 3.6), gridspec_kw={"wspace": 0.4})
    axes[0].scatter(c["fit"]["norm_pm"], c["fit"]["norm_fitted"], s=10, color="tab:green")
    lim = max(max(c["fit"]["norm_pm"]), max(c["fit"]["norm_fitted"]))
    axes[0].plot([0, lim], [0, lim], "k:", lw=1)
    axes[0].set(xlabel="‖P m‖ (train)", ylabel="‖z fitted‖", title="Code norms: fit")
    axes[1].hist(c["fit"]["cos"], bins=20, color="tab:green")
    axes[1].set(xlabel="cos(P m, z fitted)", ylabel="train samples", title="Code directions: fit")
    for name, norms in c["norm_inferred"].items():
        axes[2].hist(norms, bins=20, alpha=0.5, label=name, color=colours.get(name) or init_color(name))
    axes[2].hist(c["norm_pm_new"], bins=20, histtype="step", color="k", label="‖P m‖ (held out)")
    axes[2].set(xlabel="code norm", ylabel="held-out samples", title="Inferred code norms")
    axes[2].legend(fontsize=7)
    save_figure(fig, out / "calibration_codes.png", dpi=90)

    fig, axes = plt.subplots(1, 3, figsize=(12.5, 3.6), gridspec_kw={"wspace": 0.4})
    proj, zero = np.asarray(starts["projection"]["per_sample"]), np.asarray(starts["zero (own θ)"]["per_sample"])
    cal = np.asarray(starts["calibrated"]["per_sample"])
    for ax, other, label in ((axes[0], zero, "zero (own θ)"), (axes[1], cal, "calibrated")):
        ax.scatter(proj, other, s=8)
        lo, hi = min(proj.min(), other.min()), max(proj.max(), other.max())
        ax.plot([lo, hi], [lo, hi], "k:", lw=1)
        ax.set(
            xscale="log",
            yscale="log",
            xlabel="projection: final loss",
            ylabel=f"{label}: final loss",
            title=f"Per sample: projection vs {label}",
        )
    sens = result["sensitivity"]
    for start, vals in sens["latent_lr"].items():
        axes[2].plot(
            [float(k) for k in vals],
            list(vals.values()),
            "o-",
            label=start,
            color=colours.get(start) or init_color(start),
        )
    axes[2].set(
        xscale="log",
        yscale="log",
        xlabel="latent learning rate (inference)",
        ylabel="final held-out loss",
        title="Sensitivity to the latent learning rate",
    )
    rates = [float(k) for k in next(iter(sens["latent_lr"].values()))]
    axes[2].set_xticks(rates, [f"{v:g}" for v in rates])
    axes[2].xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
    axes[2].legend(fontsize=7)
    save_figure(fig, out / "calibration_per_sample.png", dpi=90)


if __name__ == "__main__":
    main()
