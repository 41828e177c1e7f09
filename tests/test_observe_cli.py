"""``--observe`` is a fraction (``0.25``) or a percentage (``25%``); steps only as ``--observe-steps``
(``--observe 25`` would have meant 25 steps, silently): refused in one line before any work."""

from __future__ import annotations

import pytest

from conftest import assert_user_error
from primspace.cli.observing import observed_amount, parse_amount
from primspace.utils.errors import UserError


@pytest.mark.parametrize(("text", "value"), [("0.25", 0.25), ("25%", 0.25), ("100%", 1.0), ("1.0", 1.0), ("5e-1", 0.5)])
def test_a_fraction_or_a_percentage(text, value):
    assert parse_amount(text, "--observe", ("none",)) == value


def test_steps_only_by_their_own_option():
    assert observed_amount(None, 10, "--observe", ("none",)) == 10
    assert isinstance(observed_amount(None, 10, "--observe", ("none",)), int)  # steps, not a fraction
    assert observed_amount("none", None, "--observe", ("none",)) == "none"
    assert observed_amount(None, None, "--observe", ("none",)) is None


@pytest.mark.parametrize(
    ("text", "fragments"),
    [
        ("25", ["--observe 25: write 25% for a percentage", "--observe-steps 25 for 25 steps"]),
        ("1", ["write 1%", "--observe-steps 1"]),
        ("150%", ["fraction must be in (0, 1]"]),
        ("0%", ["fraction must be in (0, 1]"]),
        ("1.5", ["fraction must be in (0, 1]"]),
        ("half", ["--observe 'half'", "25%", "--observe-steps 10"]),
    ],
)
def test_a_whole_number_or_a_bad_fraction_is_refused(text, fragments):
    with pytest.raises(UserError) as err:
        parse_amount(text, "--observe", ("none",))
    for fragment in fragments:
        assert fragment in str(err.value)


@pytest.mark.parametrize(
    ("flags", "fragments"),
    [
        (["--observe", "25"], ["--observe 25: write 25%", "--observe-steps 25"]),
        (["--observe-frames", "10"], ["--observe-frames 10: write 10%", "--observe-frames-steps 10"]),
        (["--observe", "0.5", "--observe-steps", "3"], ["give --observe 0.5 or --observe-steps 3, not both"]),
        (["--observe-steps", "0"], ["--observe-steps 0: observe at least 1 step"]),
        (["--scene", "--observe-steps", "3", "--primitive", "push"], ["--scene", "do not give --observe-steps"]),
    ],
)
def test_predict_refuses_before_reading_anything(run_cli, tmp_path, flags, fragments):
    """The run and the data named do not exist: the option is refused before they are read."""
    res = run_cli("predict", tmp_path / "run", tmp_path / "d.h5", "--out", tmp_path / "o", *flags)
    assert_user_error(res, *fragments)
    assert not (tmp_path / "o").exists()


def test_the_summary_says_the_rule_in_words_and_frames_only_for_data_with_frames():
    from primspace.cli.observing import observed_text

    rule = {"motor": 0.25, "frames": 0.25}
    assert observed_text(rule, frames=False) == "the first 25 % of the joints"  # not {'motor': 0.25, ...}
    assert observed_text(rule, frames=True) == "the first 25 % of the joints and the first 25 % of the frames"
    assert observed_text({"motor": 10, "frames": "first"}, frames=True) == (
        "the first 10 step(s) of the joints and the first step of the frames"
    )
    assert observed_text({"motor": "none", "frames": 0.5}, frames=True).startswith("none of the joints")
