"""Every command's help is complete and readable, and one concept has one option name
(issue 37: options without help, text folded mid-word, --k / --primitives / --clusters)."""

from __future__ import annotations

import re

import pytest

#: ``predict`` is being rewritten with the ``predict/`` package (issue 37, section 1);
#: its options join these checks when it lands.
_ELSEWHERE: set = set()  # every command is checked


def _commands():
    """(path, click command) of every command, sub-commands included."""
    from primspace.cli.app import click_command

    found, todo = [], [((), click_command())]
    while todo:
        path, group = todo.pop()
        for name, sub in getattr(group, "commands", {}).items():
            if getattr(sub, "commands", None):
                todo.append(((*path, name), sub))
            elif name not in _ELSEWHERE:
                found.append(((*path, name), sub))
    return sorted(found, key=lambda item: item[0])


def test_every_option_and_argument_has_help():
    missing = [
        (" ".join(path), p.opts[0] if p.opts else p.name)
        for path, command in _commands()
        for p in command.params
        if not p.hidden and not (p.help or "").strip()
    ]
    assert not missing, missing


def _help(run_cli, monkeypatch, path, width: int) -> str:
    monkeypatch.setenv("COLUMNS", str(width))
    res = run_cli(*path, "--help")
    assert res.code == 0, res.err
    return res.out


_BORDER = re.compile(r"[│╭╮╰╯─┃━]+")


def _words(text: str) -> set[str]:
    return set(_BORDER.sub(" ", text).split())


@pytest.mark.slow
def test_no_help_text_is_folded_mid_word(run_cli, monkeypatch):
    """Every word of the help at 100 columns is a word of the unwrapped help (a word folded
    across lines, "calib / rated", leaves pieces that are not); at 80 columns typer's table
    may shorten a long word with an ellipsis, but folds none."""
    broken = {}
    for path, _ in _commands():
        wide = _words(_help(run_cli, monkeypatch, path, 400))
        for width in (100, 80):
            pieces = sorted(
                w
                for w in _words(_help(run_cli, monkeypatch, path, width)) - wide
                if width == 100 or not w.endswith("…")
            )
            if pieces:
                broken[(" ".join(path), width)] = pieces
    assert not broken, broken


def test_a_choice_shows_its_name_and_its_help_lists_the_choices(run_cli, monkeypatch):
    text = " ".join(_BORDER.sub(" ", _help(run_cli, monkeypatch, ("train",), 200)).split())
    assert "<zero|random" not in text
    assert "INIT" in text and "One of: zero, random, projection, pca, calibrated, projection-vision." in text


@pytest.mark.parametrize("path", [(), ("train",), ("predict",), ("demo",)])
def test_a_flag_shows_no_type(run_cli, monkeypatch, path):
    """``--version``, ``--overwrite``: flags take no value, so their help shows none (typer showed ``<bool>``)."""
    text = _help(run_cli, monkeypatch, path, 200)
    assert "<bool>" not in text
    assert ("--version" if not path else "--help") in text


#: Names of the number of primitives (clusters) to find; only ``--primitives`` (and ``-k``) is shown.
_NUMBER_OF_PRIMITIVES = {"--k", "--clusters", "--n-clusters", "--primitives", "--n-primitives"}


def test_the_number_of_primitives_has_one_name_and_the_others_are_hidden():
    seen = {}
    for path, command in _commands():
        for p in command.params:
            names = set(p.opts) & _NUMBER_OF_PRIMITIVES
            if names:
                seen[(" ".join(path), *sorted(names))] = p.hidden
    assert seen[("cluster", "--primitives")] is False and seen[("segment", "--primitives")] is False
    assert seen[("cluster", "--k")] is True  # the deprecated name still works
    shown = {key for key, hidden in seen.items() if not hidden}
    assert all(key[1:] == ("--primitives",) for key in shown), shown


@pytest.mark.parametrize("argv, k", [(("--primitives", "3"), 3), (("-k", "3"), 3), (("--k", "3"), 3)])
def test_cluster_takes_primitives_and_its_deprecated_name(run_cli, tmp_path, argv, k):
    import json

    import numpy as np

    rng = np.random.default_rng(0)
    z = tmp_path / "z.npy"
    np.save(z, np.concatenate([rng.standard_normal((20, 2)) @ rng.standard_normal((2, 5)) + 5 * i for i in range(3)]))
    res = run_cli("cluster", z, *argv, "--out", tmp_path / "out", "--json")
    assert res.code == 0, res.err
    assert json.loads(res.out)["n_clusters"] == k


def test_cluster_needs_the_number_of_primitives_once(run_cli, tmp_path):
    from conftest import assert_user_error

    z = tmp_path / "z.npy"
    __import__("numpy").save(z, __import__("numpy").zeros((5, 2)))
    assert_user_error(run_cli("cluster", z, "--out", tmp_path / "o"), "--primitives")
    assert_user_error(run_cli("cluster", z, "-k", "2", "--k", "2", "--out", tmp_path / "o"), "--primitives", "--k")


#: The positional argument that names a data set, by command: shown as DATA everywhere.
_DATA_ARGUMENT = {"train": "file", "infer": "file", "info": "file", "show": "file", "cluster": "src", "segment": "data"}


def test_the_data_argument_has_one_name():
    commands = dict((" ".join(path), command) for path, command in _commands())
    shown = {name: {p.name: p.metavar for p in commands[name].params}[param] for name, param in _DATA_ARGUMENT.items()}
    assert shown == {name: "DATA" for name in _DATA_ARGUMENT}


def test_info_on_long_demonstrations_names_their_classes_not_unknown_samples():
    """A long demonstration has no class of its own (label -1): its steps are labelled. info
    said "<unknown> 72" for 72 of them; it names the classes and points at the steps line."""
    from primspace.cli.data import _labels_line

    long = {"grasp": 0, "push": 0, "<unknown>": 72}
    assert _labels_line(long, per_step=True) == "  labels   2 classes, per step (below): grasp, push"
    mixed = _labels_line({"grasp": 3, "push": 2, "<unknown>": 1}, per_step=False)
    assert mixed == "  labels   2 classes: grasp 3, push 2; unlabelled 1" and "<unknown>" not in mixed
    assert _labels_line(None, per_step=False) == "  labels   none"


def test_a_table_cell_never_shows_a_python_dict():
    from primspace.cli.options import cell_text

    assert cell_text({"taus": (2.0, 8.0), "latent_lr": 0.03}) == "taus 2, 8, latent_lr 0.03"
    assert cell_text(0.123456) == "0.1235" and cell_text("x") == "x"
