"""Experiments flow one way: compute -> results -> figures -> report (issue 12, item 5).

The report reads results and imports no experiment; no experiment imports the report;
figures are drawn from arrays; the demo sits above both. Checked on the source (``ast``),
by importing every module, and on an experiment directory written by an older version.
"""

from __future__ import annotations

import ast
import importlib
import json
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

import primspace

SRC = Path(primspace.__file__).resolve().parent

# the package that reads results (readers, tables, claims) and imports no experiment
RESULTS = "primspace.results"


def _modules(package: str) -> list[str]:
    pkg = importlib.import_module(package)
    names = [package]
    if hasattr(pkg, "__path__"):
        names += [m.name for m in pkgutil.walk_packages(pkg.__path__, prefix=f"{package}.")]
    return names


def _source(module: str) -> Path:
    rel = Path(*module.split(".")[1:])
    path = SRC / rel / "__init__.py"
    return path if path.exists() else SRC / rel.with_suffix(".py")


def _imports(module: str) -> set[str]:
    """Every primspace module ``module`` imports, at any depth of its code (lazy imports included)."""
    tree = ast.parse(_source(module).read_text(encoding="utf-8"))
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            # "from primspace.experiments import figures" imports a module, not a name
            found |= {f"{node.module}.{a.name}" for a in node.names if _is_module(f"{node.module}.{a.name}")}
    return {m for m in found if m.startswith("primspace")}


def _is_module(name: str) -> bool:
    return _source(name).exists() if name.startswith("primspace.") else False


def _within(name: str, package: str) -> bool:
    return name == package or name.startswith(package + ".")


@pytest.mark.parametrize(
    "package", ["primspace.results", "primspace.report", "primspace.experiments", "primspace.plots", "primspace.demo"]
)
def test_every_module_imports(package):
    for name in _modules(package):
        importlib.import_module(name)


def test_the_report_imports_only_the_results_readers():
    for module in _modules("primspace.report"):
        bad = {m for m in _imports(module) if _within(m, "primspace.experiments")}
        assert not bad, (module, bad)
        assert "primspace.demo" not in _imports(module)
    assert any(_within(m, RESULTS) for module in _modules("primspace.report") for m in _imports(module))


def test_no_experiment_imports_the_report_or_the_demo():
    for module in _modules("primspace.experiments"):
        bad = {m for m in _imports(module) if _within(m, "primspace.report") or _within(m, "primspace.demo")}
        assert not bad, (module, bad)


def test_readers_and_figures_import_no_experiment():
    readers = _modules(RESULTS)
    assert {f"{RESULTS}.layout", f"{RESULTS}.readers", f"{RESULTS}.claims", f"{RESULTS}.measures"} <= set(readers)
    for module in readers:
        others = {m for m in _imports(module) if _within(m, "primspace.experiments")}
        assert not others, (module, others)
    others = {m for m in _imports("primspace.experiments.figures") if _within(m, "primspace.experiments")}
    assert not others, others


def test_every_experiment_command_prints_a_table_of_the_results_package():
    """``primspace experiment NAME`` prints ``table``: a function of ``results.tables``, or
    ``module:function`` of another module of ``primspace.results`` (cli/experiments.py)."""
    tree = ast.parse((SRC / "cli" / "experiments.py").read_text(encoding="utf-8"))
    tables = [
        node.args[3].value
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
        and getattr(node.func, "id", None) == "_experiment_command"
        and len(node.args) > 3
        and isinstance(node.args[3], ast.Constant)
        and node.args[3].value is not None
    ]
    assert {"final_loss_table", "composite:composite_table", "act:act_table"} <= set(tables), tables
    for table in tables:
        module, _, function = table.rpartition(":")
        assert callable(getattr(importlib.import_module(f"{RESULTS}.{module or 'tables'}"), function)), table


def test_figures_never_run_a_model():
    for module in _modules("primspace.plots"):
        bad = {
            m
            for m in _imports(module)
            if any(
                _within(m, p)
                for p in (
                    "primspace.train",
                    "primspace.model.decoder",
                    "primspace.experiments",
                    "primspace.report",
                    "primspace.demo",
                )
            )
        }
        assert not bad, (module, bad)


def test_importing_the_report_loads_no_experiment():
    code = (
        "import sys, primspace.report; print(sorted(m for m in sys.modules if m.startswith('primspace.experiments')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert json.loads(out.replace("'", '"')) == []


# ------------------------------------------------- an experiment directory of an older version


def _old_experiment_dir(path: Path) -> Path:
    """experiment.json with the flat preset of older versions, and intra results; no
    data summary, no Appendix A results, no figures."""
    flat = {
        "name": "demo",
        "data_preset": "demo",
        "train_fraction": 0.2,
        "inits": ["zero", "random", "projection"],
        "latent_dims": [8],
        "seeds": [0],
        "fit_epochs": 400,
        "infer_epochs": 250,
        "batch_size": 16,
        "infer_batch_size": 256,
        "lr": 0.003,
        "latent_lr": 0.03,
        "final_lr_fraction": 0.1,
        "images": False,
        "vision_weight": 1.0,
        "layer_sizes": [32, 12],
        "taus": [2.0, 8.0],
        "cluster_latent_dim": 40,
        "cluster_r2": 0.9999,
        "trajectory_r2": 0.9,
        "lasa_length": 100,
        "inter_latent_dim": 20,
        "inter_inits": ["zero", "projection"],
        "inter_epochs": [100, 100],
        "inter_replay": 0.1,
        "extra": {},
    }
    meta = {"preset": "demo", "preset_config": flat, "data": str(path / "gone.h5"), "timings": {"intra": 1.0}}
    (path / "results").mkdir(parents=True)
    (path / "experiment.json").write_text(json.dumps(meta))

    def run(init, fit, infer):
        return {
            "init": init,
            "latent_dim": 8,
            "seed": 0,
            "key": f"intra/{init}-q8-s0",
            "fit": [{"epoch": e, "loss": v} for e, v in enumerate(fit)],
            "infer": [{"epoch": e, "loss": v} for e, v in enumerate(infer)],
        }

    intra = {
        "runs": [
            run("zero", [1.0, 0.1], [0.5, 0.2]),
            run("random", [1.0, 0.3], [0.6, 0.3]),
            run("projection", [1.0, 0.05], [0.1, 0.01]),
        ],
        "failures": {},
        "splits": {"0": {"n_train": 28, "n_eval": 98}},
        "label_names": ["touch", "grasp"],
    }
    (path / "results" / "intra.json").write_text(json.dumps(intra))
    return path


def test_the_report_reads_an_old_directory_and_computes_nothing(tmp_path, monkeypatch):
    import primspace.model.latent
    import primspace.train
    from primspace.report import build_report

    def forbidden(*args, **kwargs):
        raise AssertionError("the report computed something")

    for module, name in (
        (primspace.model.latent, "appendix_a_check"),
        (primspace.train, "reconstruct"),
        (primspace.train, "load_run"),
        (primspace.train, "fit"),
        (primspace.train, "infer"),
    ):
        monkeypatch.setattr(module, name, forbidden)
    out = _old_experiment_dir(tmp_path / "old")
    html = build_report(out).read_text()
    for heading in (
        "Summary",
        "claims, checked",
        "Data",
        "Intra-primitive generalisation",
        "Appendix A",
        "Configuration, versions, timings",
    ):
        assert f">{heading}" in html or heading in html, heading
    assert "No data summary here" in html and "appendix_a.json" in html and "Not computed here" in html
    assert "figure missing: intra_loss_fit" in html  # said, not drawn
    assert not (out / "results" / "appendix_a.json").exists() and not (out / "figures").exists()


def test_an_old_flat_preset_reads_as_the_same_configurations():
    from dataclasses import replace

    from primspace.experiments.presets import PRESETS, ExperimentPreset
    from primspace.experiments.runs import train_configs
    from primspace.model.config import ModelConfig
    from primspace.train import TrainConfig

    flat = json.loads(json.dumps(PRESETS["demo"].to_dict()))  # then in the old, flat form:
    model, train = flat.pop("model"), flat.pop("train")
    flat |= {k: model[k] for k in ("layer_sizes", "taus")}
    flat |= {k: train[k] for k in ("batch_size", "lr", "latent_lr", "final_lr_fraction", "vision_weight")}
    old = ExperimentPreset.from_dict(flat)
    assert old == PRESETS["demo"]
    # what the old code built by hand, field by field, for one run
    mc, tc = train_configs(old, 40, 3, 400)
    assert mc == ModelConfig(latent_dim=40, layer_sizes=(32, 12), taus=(2.0, 8.0))
    assert tc == TrainConfig(
        epochs=400,
        batch_size=16,
        lr=3e-3,
        latent_lr=3e-2,
        final_lr_fraction=0.1,
        vision_weight=1.0,
        seed=3,
        checkpoint_every=40,
        threads=1,
    )
    assert replace(PRESETS["paper"].train, epochs=1) == TrainConfig(epochs=1, final_lr_fraction=0.1, threads=1)
    with pytest.raises(Exception, match="both flat and inside"):
        ExperimentPreset.from_dict({**PRESETS["demo"].to_dict(), "lr": 0.1})


def test_a_results_file_that_is_a_link_is_refused(tmp_path):
    """A results file linked to another file would put that file's text into the report."""
    from primspace.results.readers import read_results
    from primspace.utils.errors import UserError

    (tmp_path / "results").mkdir()
    secret = tmp_path / "secret.json"
    secret.write_text('{"runs": []}')
    (tmp_path / "results" / "intra.json").symlink_to(secret)
    with pytest.raises(UserError, match="not a regular file"):
        read_results(tmp_path, "intra")


# ------------------------------------------------- the act experiment's results (issue 40)

ACT_SCENE_ROWS = ["scene policy", "contextual ProMP (pixels)"]
ACT_LOOP_ROWS = ["closed loop", "open loop"]


def fake_act_results() -> dict:
    """An act results dict as ``run_act`` writes it: 2 seeds, two rows of each part, push and pull."""
    from primspace.experiments.act import act_summary

    def entry(n, success, mse=None):
        return {"n": n, "success": success} | ({} if mse is None else {"mse": mse})

    by_seed = {}
    for seed, shift in (("0", 0.0), ("1", 0.1)):

        def part(rows, mse):
            return {
                row: {
                    "push": entry(3, 0.5 + shift - 0.2 * i, 0.01 * (i + 1) if mse else None),
                    "pull": entry(4, 0.25 + shift, 0.02 * (i + 1) if mse else None),
                    "all": entry(7, 0.4 + shift - 0.1 * i, 0.015 * (i + 1) if mse else None),
                }
                for i, row in enumerate(rows)
            }

        by_seed[seed] = {
            "scene": part(ACT_SCENE_ROWS, True),
            "loop": part(ACT_LOOP_ROWS, False),
            "latency_ms": {"median": 0.8 + shift, "p95": 1.5 + shift, "max": 3.0 + shift},
            "n_fitted": 21,
            "n_test": 7,
            "has_image_head": False,
        }
    return {
        "latent_dim": 40,
        "every": 6,
        "perturbation": {"at": 0.3, "distance_m": [0.02, 0.04]},
        "scene_rows": ACT_SCENE_ROWS,
        "loop_rows": ACT_LOOP_ROWS,
        "by_seed": by_seed,
        "failures": {},
        "table": act_summary(by_seed),
    }


def act_experiment_dir(path: Path) -> Path:
    """An experiment directory (:func:`_old_experiment_dir`) with act results and an act animation."""
    out = _old_experiment_dir(path)
    (out / "results" / "act.json").write_text(json.dumps(fake_act_results()))
    (out / "figures").mkdir()
    (out / "figures" / "act.gif").write_bytes(b"GIF89a\x01\x00\x01\x00\x00\x00\x00;")
    return out


def test_the_act_tables_are_read_without_an_experiment():
    from primspace.experiments.act import act_tables as from_experiment
    from primspace.results.act import act_tables

    results = fake_act_results()
    tables = act_tables(results)
    assert tables == from_experiment(results)
    assert [t[0] for t in tables] == [
        "Scene only: success (2 seeds)",
        "Scene only: MSE of the steps after the first, scaled (2 seeds)",
        "Block moved at 30 %: success (2 seeds)",
    ]
    title, columns, rows = tables[0]
    assert columns == ["method", "push", "pull", "all"]
    assert [r[0] for r in rows] == ACT_SCENE_ROWS
    assert rows[0][1] == "0.55 ± 0.07"  # push: 0.5 and 0.6, std ddof 1


def test_the_summary_keeps_the_act_results_small(tmp_path):
    from primspace.results.act import act_tables
    from primspace.results.summary import _round, summarize

    out = act_experiment_dir(tmp_path / "exp")
    results = fake_act_results()
    kept = summarize(out, "act-test", "primspace experiment act --out exp")["results"]["act"]
    assert kept["table"] == _round(results["table"])
    assert kept["scene_rows"] == ACT_SCENE_ROWS and kept["loop_rows"] == ACT_LOOP_ROWS
    assert kept["seeds"] == [0, 1] and kept["every"] == 6 and kept["latent_dim"] == 40
    seed = kept["by_seed"]["0"]
    assert seed["latency_ms"] == results["by_seed"]["0"]["latency_ms"] and seed["n_test"] == 7
    assert seed["scene"]["scene policy"] == {"n": 7, "success": 0.4, "mse": 0.015}  # "all" only
    assert "push" not in json.dumps(kept["by_seed"])
    assert act_tables(kept) == act_tables(results)


def test_the_report_has_the_act_section_with_its_tables_and_animation(tmp_path):
    from primspace.report import build_report

    html = build_report(act_experiment_dir(tmp_path / "exp")).read_text()
    assert "Acting from the scene and in closed loop" in html
    for text in ACT_SCENE_ROWS + ACT_LOOP_ROWS + ["Block moved at 30 %: success (2 seeds)", "0.55 ± 0.07"]:
        assert text in html, text
    assert "every 6 steps" in html and "2-4 cm at 30 % of the motion" in html and "ddof 1" in html
    assert "median 0.85 ± 0.07 ms over seeds (p95 up to 1.6 ms, max up to 3.1 ms)" in html
    assert "data:image/gif" in html
