"""The numbers of README, docs/results.md, docs/predict.md and docs/sequences.md are
generated from the stored summaries (docs/results/*.json) by ``python -m
primspace.report.markdown``: the committed text must equal what it writes, so no number
in those blocks is typed by hand or left stale."""

import re
from pathlib import Path

import pytest

from primspace.report.markdown import g, main, mean_spread, replace_blocks

ROOT = Path(__file__).resolve().parents[1]


def test_committed_docs_equal_what_the_summaries_give(capsys):
    assert main(["--root", str(ROOT), "--check"]) == 0, capsys.readouterr().err


def test_a_stale_block_is_found_and_rewritten(tmp_path):
    _copy_targets(tmp_path)
    readme = tmp_path / "README.md"
    readme.write_text(
        readme.read_text().replace("<!-- generated: glance -->\n", "<!-- generated: glance -->\nhand-typed 0.99\n")
    )
    (tmp_path / "docs" / "results").mkdir()
    for summary in (ROOT / "docs" / "results").glob("*.json"):
        (tmp_path / "docs" / "results" / summary.name).write_text(summary.read_text())
    assert main(["--root", str(tmp_path), "--check"]) == 1
    assert "hand-typed" in readme.read_text()  # --check writes nothing
    assert main(["--root", str(tmp_path)]) == 0
    assert "hand-typed" not in readme.read_text()
    assert main(["--root", str(tmp_path), "--check"]) == 0


def _copy_targets(root: Path) -> None:
    """Every file with generated blocks, copied from the repository into ``root``."""
    from primspace.report.markdown import TARGETS

    for target in dict.fromkeys(TARGETS.values()):
        (root / target).parent.mkdir(parents=True, exist_ok=True)
        (root / target).write_text((ROOT / target).read_text(encoding="utf-8"), encoding="utf-8")


def test_without_an_act_summary_docs_act_says_so():
    from primspace.report.markdown import NO_ACT, TARGETS, blocks, load_summaries

    assert NO_ACT == "No act summary is committed yet."
    assert TARGETS["act"] == Path("docs") / "act.md"
    assert blocks({})["act"] == NO_ACT
    if not any("act" in s["results"] for s in load_summaries(ROOT).values()):
        assert (
            f"<!-- generated: act -->\n{NO_ACT}\n<!-- end generated: act -->" in (ROOT / "docs" / "act.md").read_text()
        )


def test_the_act_tables_are_written_into_docs_act_md(tmp_path):
    """A summary of an experiment directory with act results (built from a fake results
    dict) gives docs/act.md its three tables and the latency line."""
    from primspace.report.markdown import NO_ACT, blocks
    from primspace.results.summary import summarize, write_summary
    from primspace.utils.stats import spread_convention
    from test_report_layers import ACT_LOOP_ROWS, ACT_SCENE_ROWS, act_experiment_dir

    summary = summarize(act_experiment_dir(tmp_path / "exp"), "act-test", "primspace experiment act --out exp")
    text = blocks({"act-test": summary})["act"]
    # the page states the convention of its spreads once, atop the block
    assert text.startswith(spread_convention() + "\n\n#### act-test\n\n```\nprimspace experiment act --out exp\n```")
    assert "q = 40, seeds 0, 1 (7 scenes each); the block moved 2-4 cm at 30 % of the motion" in text
    assert "re-asked every 6 steps; mean ± sample std (ddof 1) over seeds." in text
    for title in (
        "**Scene only: success (2 seeds)**",
        "**Scene only: MSE of the steps after the first, scaled (2 seeds)**",
        "**Block moved at 30 %: success (2 seeds)**",
    ):
        assert title in text
    assert "| method | push | pull | all |" in text
    for row in ACT_SCENE_ROWS + ACT_LOOP_ROWS:
        assert f"| {row} | " in text, row
    assert "| scene policy | 0.55 ± 0.07 |" in text and "median 0.85 ± 0.07 ms" in text

    root = tmp_path / "repo"
    _copy_targets(root)
    (root / "docs" / "results").mkdir()
    write_summary(root / "docs" / "results" / "act-test.json", summary)
    assert main(["--root", str(root)]) == 0
    act_md = (root / "docs" / "act.md").read_text()
    assert text in act_md and NO_ACT not in act_md
    assert act_md.startswith((ROOT / "docs" / "act.md").read_text().split("<!-- generated: act -->")[0])
    assert main(["--root", str(root), "--check"]) == 0


def test_blocks_are_replaced_between_their_markers_only():
    text = "a\n<!-- generated: x -->\nold\n<!-- end generated: x -->\nb"
    assert replace_blocks(text, {"x": "new"}) == "a\n<!-- generated: x -->\nnew\n<!-- end generated: x -->\nb"
    empty = "<!-- generated: x -->\n<!-- end generated: x -->"
    assert replace_blocks(empty, {"x": "new"}) == "<!-- generated: x -->\nnew\n<!-- end generated: x -->"
    with pytest.raises(ValueError, match="no generated block 'y'"):
        replace_blocks(text, {"y": "new"}, "f.md")


def test_numbers_are_printed_with_their_spread():
    assert g(2.7e-05) == "2.7e-5" and g(0.123456) == "0.12" and g(None) == "—" and g(float("nan")) == "—"
    assert g(2e-4) == "2.0e-4" and g(0.0012) == "0.0012" and g(1234.5) == "1.2e3"
    # sample std (ddof 1): [1e-4, 3e-4] -> sqrt(2e-8 / 1) = 1.41e-4, one digit: 1e-4
    assert mean_spread([1e-4, 3e-4]) == "2.0e-4 ± 1e-4 [1.0e-4–3.0e-4]"
    assert mean_spread([0.5]) == "0.5"  # one seed: no spread to show
    assert mean_spread([None, 0.5]) == "0.5" and mean_spread([]) == "—"


def test_the_spread_is_the_sample_std():
    """ddof 1, not numpy's default 0: [0.8, 0.9, 1.0] has squared deviations 0.01 + 0 + 0.01,
    so std = sqrt(0.02 / 2) = 0.1 (the population std, sqrt(0.02 / 3) = 0.082, printed 0.08
    before issue 42); the 95 % t half-width is t(0.975, 2) · 0.1 / sqrt(3) = 4.303 · 0.1 / 1.732
    = 0.248, printed with one digit: 0.2."""
    assert mean_spread([0.8, 0.9, 1.0], rng=False) == "0.9 ± 0.1"
    assert mean_spread([0.8, 0.9, 1.0], rng=False, ci=True) == "0.9 ± 0.1 (95 % CI ± 0.2)"
    assert mean_spread([0.8, 0.9, 1.0], rng=True) == "0.9 ± 0.1 [0.8–1]"
    # three digits: the std printed with two; [28, 30]: sqrt(2 / 1) = 1.41; t(0.975, 1) · 1.41 / sqrt(2) = 12.7
    assert mean_spread([28.0, 30.0], 3, rng=False, ci=True) == "29 ± 1.4 (95 % CI ± 13)"


def _summary(name, motor, psnr):
    runs = [
        {
            "init": init,
            "latent_dim": 40,
            "seed": s,
            "fit": [{"epoch": 0, "loss": 1.0}],
            "infer": [{"epoch": 0, "loss": 1.0}],
            "final": {"fit": {}, "infer": {"motor": m, "psnr": p}},
        }
        for init, ms in motor.items()
        for s, (m, p) in enumerate(zip(ms, psnr[init]))
    ]
    return {"name": name, "results": {"intra": {"runs": runs}}}


def test_two_summaries_are_compared_side_by_side_on_per_element_errors():
    from primspace.report.markdown import render_comparison

    a = _summary(
        "mean", {"projection": [1e-4, 3e-4], "zero": [1e-3, 1e-3]}, {"projection": [28.0, 30.0], "zero": [27.0, 27.0]}
    )
    b = _summary(
        "sum", {"projection": [2e-3, 2e-3], "zero": [4e-3, 6e-3]}, {"projection": [29.0, 29.0], "zero": [28.0, 28.0]}
    )
    text = render_comparison(a, b, "two losses")
    assert text.startswith("#### mean against sum: two losses")
    # sample std (ddof 1): psnr [28, 30] -> 1.41 (two digits at three-digit means); motor [4e-3, 6e-3] -> 1.4e-3
    assert "| projection | 2.0e-4 ± 1e-4 | 0.002 ± 0 | 29 ± 1.4 | 29 ± 0 |" in text
    assert "| zero | 0.001 ± 0 | 0.005 ± 0.001 |" in text


def test_readmes_table_says_whether_projection_leads_zero_and_pca_after_tuning():
    """Where a summary holds the tuned baselines, README's table counts the seeds where
    projection's final eval loss is below zero's and pca's at the tuned q, tuned (counted
    here again from the summary's runs, seed by seed)."""
    import json

    from primspace.report.markdown import glance

    summary = json.loads((ROOT / "docs" / "results" / "lasa.json").read_text())
    tune, intra = summary["results"]["tune"], summary["results"]["intra"]
    q = tune["latent_dim"]

    def below(runs, init):
        last = {(r["init"], r["seed"]): r["infer"][-1]["loss"] for r in runs if r["latent_dim"] == q}
        seeds = sorted(s for i, s in last if i == init and ("projection", s) in last)
        return f"{sum(last[('projection', s)] < last[(init, s)] for s in seeds)} of {len(seeds)}"

    text = glance({"lasa": summary})
    row = next(line for line in text.splitlines() if line.startswith("| *lasa* |"))
    assert f"| {below(tune['tuned']['runs'], 'zero')} / {below(tune['tuned']['runs'], 'pca')} (q = {q}) |" in row
    seeds = len({r["seed"] for r in intra["runs"]})
    assert row.startswith(f"| *lasa* | {seeds} | {max(r['latent_dim'] for r in intra['runs'])} |")
    del summary["results"]["tune"]
    assert "(q = " not in glance({"lasa": summary})


def test_readmes_table_reads_a_tune_run_in_another_directory():
    """A summary named in TUNED_IN gets its tuned cell from the summary named there (the
    paper preset's q = 20 was tuned in its own directory); that summary itself stays out
    of the table (not in ORDER)."""
    import json

    from primspace.report.markdown import TUNED_IN, glance

    name = next(iter(TUNED_IN))
    lasa = json.loads((ROOT / "docs" / "results" / "lasa.json").read_text())
    plain = json.loads(json.dumps(lasa))
    del plain["results"]["tune"]
    text = glance({name: plain, TUNED_IN[name]: lasa})
    assert text.count("(q = ") == 1
    assert f"*{name}*" in text and f"*{TUNED_IN[name]}*" not in text
    assert "(q = " not in glance({name: plain})


def test_a_tune_run_on_copied_runs_shows_only_its_tuning_table():
    """docs/results.md shows the summary a TUNED_IN entry names by its tuning table
    alone (its shared-setting runs are the other summary's, shown there); without the
    other summary stored, it is shown whole."""
    import json

    from primspace.report.markdown import TUNED_IN, blocks

    name = next(iter(TUNED_IN))
    lasa = json.loads((ROOT / "docs" / "results" / "lasa.json").read_text())
    tuned = dict(lasa, name=TUNED_IN[name])
    plain = json.loads(json.dumps(lasa))
    del plain["results"]["tune"]
    plain["name"] = name
    text = blocks({name: plain, TUNED_IN[name]: tuned})["results"]
    section = text[text.index(f"#### {TUNED_IN[name]}") :]
    assert "Fair baselines" in section
    assert "Losses (mean" not in section and "The paper's sentences" not in section
    alone = blocks({TUNED_IN[name]: tuned})["results"]
    assert "Losses (mean" in alone and "Fair baselines" in alone


def test_a_side_of_a_comparison_may_be_several_summaries_one_per_init():
    # rates tuned per init: one experiment each, compared as one setting (issue 42's ablation)
    from primspace.report.markdown import merged, render_comparison

    rescaled = lambda init, acc: [  # noqa: E731
        {"init": init, "seed": 0, "rescaling": how, "rms": 2.0, "accuracy": acc}
        for how in ("common scale", "standardised per dimension")
    ]
    a = _summary("adam", {"zero": [1e-3], "projection": [2e-4]}, {"zero": [None], "projection": [None]})
    a["results"]["clustering"] = {
        "latent": [],
        "by_seed": {},
        "rescaled": rescaled("zero", 0.4) + rescaled("projection", 0.8),
    }
    zero = _summary("sgd-zero", {"zero": [3e-3]}, {"zero": [None]})
    zero["results"]["clustering"] = {"latent": [], "by_seed": {}, "rescaled": rescaled("zero", 0.7)}
    proj = _summary("sgd-projection", {"projection": [5e-4]}, {"projection": [None]})
    proj["results"]["clustering"] = {"latent": [], "by_seed": {}, "rescaled": rescaled("projection", 0.9)}
    summaries = {s["name"]: s for s in (a, zero, proj)}
    both = merged(summaries, ("sgd-zero", "sgd-projection"))
    assert both["name"] == "sgd-zero + sgd-projection" and len(both["results"]["intra"]["runs"]) == 2
    assert merged(summaries, "adam") is a
    text = render_comparison(a, both, "Adam against SGD")
    assert "| zero | 0.001 | 0.003 |" in text and "clustering, common scale: sgd-zero + sgd-projection" in text
    assert "| 0.4 | 0.7 | 0.4 | 0.7 |" in text  # each init's rescaled accuracies, from its own summary


def _clustered(seed_acc: dict, rescaled: dict | None = None) -> dict:
    """A summary whose clustering holds ``{seed: (zero, projection)}`` learned accuracies."""
    rows = {
        s: [{"init": i, "codes": "learned", "accuracy": a} for i, a in zip(("zero", "projection"), acc)]
        for s, acc in seed_acc.items()
    }
    first = min(rows)
    scaled = [
        {"init": i, "seed": s, "rescaling": how, "rms": 1.0, "accuracy": a}
        for how, by_seed in (rescaled or {}).items()
        for s, acc in by_seed.items()
        for i, a in zip(("zero", "projection"), acc)
    ]
    clustering = {
        "seed": first,
        "latent": rows[first],
        "by_seed": {str(s): r for s, r in rows.items() if s != first},
        "rescaled": scaled,
    }
    return {"name": "x", "results": {"clustering": clustering}}


def test_the_clustering_ablation_reads_its_rule():
    # docs/reproduce.md: the gap (projection - zero, per seed) is gone when |g| <= s and it shrank by more than both spreads
    import numpy as np

    from primspace.report.markdown import clustering_ablation, clustering_gaps

    adam_acc = {0: (0.45, 0.89), 1: (0.40, 0.79), 2: (0.50, 0.82)}  # gaps 0.44, 0.39, 0.32
    same = {"common scale": adam_acc}
    adam = _clustered(adam_acc, same)
    assert np.allclose(clustering_gaps(adam)["as they are"], [0.44, 0.39, 0.32])
    text = clustering_ablation(adam, _clustered({0: (0.88, 0.89), 1: (0.80, 0.79), 2: (0.81, 0.82)}))
    assert "the optimiser explains the gap" in text and "the scale does not explain it" in text
    text = clustering_ablation(adam, _clustered({0: (0.6, 0.89), 1: (0.5, 0.79), 2: (0.6, 0.82)}))
    assert "the optimiser does not explain the gap" in text


#: A path of one machine: its temporary, home, work or user folders, or a drive.
MACHINE_PATH = re.compile(r"(?<![\w.])(/tmp/|/root/|/home/|/work/|/Users/|[A-Z]:\\)")
#: The benchmarks' shared lock (benchmarks/bench_*.py ``flock`` it): a path every machine has.
SHARED_LOCK = "/tmp/primspace-bench.lock"


def test_no_doc_holds_a_path_of_one_machine():
    """Commands in README and docs/*.md run on a reader's machine: the generated ones print
    placeholders (``OUT``, ``DATA.h5``) where the stored summaries keep the paths they ran with."""
    found = [
        f"{path.relative_to(ROOT)}:{n}: {line.strip()[:160]}"
        for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if MACHINE_PATH.search(line.replace(SHARED_LOCK, ""))
    ]
    assert not found, "paths of one machine in the docs:\n" + "\n".join(found)
    assert MACHINE_PATH.search("--out /work/runs/x") and MACHINE_PATH.search("C:\\runs")
    assert not MACHINE_PATH.search("https://example.org/home/x --out OUT")


def test_a_stored_command_is_printed_with_placeholders_for_its_paths():
    from primspace.report.commands import portable_command

    stored = (
        "primspace experiment intra --preset paper --data /work/runs/a/data.h5 --out /tmp/w/exp/b --workers 2\n"
        "primspace experiment clustering --data /tmp/w/exp/b/data.h5 --out=/tmp/w/exp/b --json C:\\x\\r.json -o rel"
    )
    assert portable_command(stored) == (
        "primspace experiment intra --preset paper --data DATA.h5 --out OUT --workers 2\n"
        "primspace experiment clustering --data OUT/data.h5 --out=OUT --json JSON.json -o rel"
    )
    kept = "primspace experiment act --out exp --note 'two  spaces'"
    assert portable_command(kept) == kept


def test_a_stored_command_the_cli_no_longer_has_is_marked_retired():
    from primspace.cli.app import main as cli_main
    from primspace.report.commands import RETIRED, portable_command

    stored = "primspace experiment scene --preset demo --out /tmp/w/exp/b"
    assert (
        portable_command(stored)
        == "primspace experiment scene --preset demo --out OUT  # retired in 0.9.0: no longer runs"
    )
    for command in RETIRED:  # each one really is gone from the CLI
        with pytest.raises(SystemExit) as exited:
            cli_main(command.split()[1:] + ["--help"])
        assert exited.value.code == 2
