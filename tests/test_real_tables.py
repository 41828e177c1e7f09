"""docs/real.md's block: one row per summary of the real preset, its verdict and what explains it."""

import numpy as np

from primspace.report.markdown import blocks
from primspace.report.real_tables import NO_REAL, REAL, is_real, render_real
from primspace.results.codes import VERSION_KEY, write_codes


def _summary(name, zero, projection, preset=REAL):
    runs = []
    for init, losses in (("zero", zero), ("projection", projection)):
        for seed, loss in enumerate(losses):
            runs.append(
                {
                    "init": init,
                    "latent_dim": 2,
                    "seed": seed,
                    "n_train": 4,
                    "n_eval": 16,
                    "fit": [{"epoch": 0, "loss": 0.5}, {"epoch": 400, "loss": 0.001}],
                    "infer": [{"epoch": 0, "loss": 0.2}, {"epoch": 250, "loss": loss}],
                }
            )
    return {
        "name": name,
        "command": "primspace experiment intra --preset real --data /somewhere/x.h5 --out /runs/x",
        "note": "",
        "preset": {"name": preset},
        "data": {"length": 10, "n_joints": 3, "label_names": ["a", "b"]},
        "results": {"intra": {"runs": runs, "label_names": ["a", "b"]}},
        "codes": {"file": f"{name}.codes.npz"},
    }


def _codes(folder, name):
    rng = np.random.default_rng(1)
    arrays = {VERSION_KEY: np.array(1), "runs": np.array(["intra/projection-q2-s0", "intra/zero-q2-s0"])}
    pm = rng.standard_normal((20, 2)) * [4.0, 1.0]
    for key, fit, init in (("intra/projection-q2-s0", pm, pm), ("intra/zero-q2-s0", pm * 0 + 0.5, pm * 0)):
        arrays |= {
            f"{key}/fit/latents": fit[:4],
            f"{key}/fit/latents_init": init[:4],
            f"{key}/fit/indices": np.arange(4),
            f"{key}/infer/latents": fit[4:],
            f"{key}/infer/latents_init": init[4:],
            f"{key}/infer/indices": np.arange(4, 20),
        }
    write_codes(folder / f"{name}.codes.npz", arrays)


def test_real_block_gives_losses_verdict_and_why(tmp_path, monkeypatch):
    (tmp_path / "docs" / "results").mkdir(parents=True)
    _codes(tmp_path / "docs" / "results", "real-x")
    monkeypatch.chdir(tmp_path)  # the codes are read from docs/results/, as the generator does
    text = render_real({"real-x": _summary("real-x", [0.002, 0.0019, 0.0021], [0.008, 0.0079, 0.0081])})
    assert "OUT" in text and "DATA.h5" in text and "/somewhere" not in text  # portable commands
    row = next(line for line in text.splitlines() if line.startswith("| *real-x* | 4 / 16"))
    assert "**does not hold**" in row and "reversed" in row
    assert "0.002 ± 1e-4" in row and "0.008 ± 1e-4" in row
    why = next(line for line in text.splitlines() if line.startswith("| *real-x* | 30 / 2"))
    rng = np.random.default_rng(1)  # the codes _codes wrote: P m, and zero's fit at 0.5 in each of 2 dimensions
    pm_norm = np.linalg.norm(rng.standard_normal((20, 2)) * [4.0, 1.0], axis=1).mean()
    cells = [c.strip() for c in why.split("|")[1:-1]]
    assert cells[2:5] == [f"{pm_norm:.2g}", "0.71", f"{pm_norm / np.sqrt(0.5):.2g}"]
    assert cells[5] == "0"  # projection's fit did not move its codes


def test_only_real_summaries_go_to_real_md_not_to_results_md(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no codes stored: the why table says so with dashes
    real = _summary("real-x", [0.01, 0.011, 0.012], [0.002, 0.003, 0.004])
    other = _summary("other", [0.01, 0.011, 0.012], [0.002, 0.003, 0.004], preset="demo")
    assert is_real(real) and not is_real(other)
    out = blocks({"real-x": real})
    assert "**holds**" in out["real"]
    assert "real-x" not in out["results"]
    assert render_real({"other": other}) == NO_REAL
