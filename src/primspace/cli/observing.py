"""How much of each motion ``predict`` observes, as the command line writes it: ``--observe`` and
``--observe-frames`` (a fraction, ``0.25`` or ``25%``), ``--observe-steps`` and
``--observe-frames-steps`` (a number of steps), parsed into the library's amounts (a float
fraction, an int number of steps, or a word), and a rule said back in words."""

from __future__ import annotations

import math

from primspace.utils.errors import UserError

__all__ = ["observed_amount", "observed_text", "parse_amount"]


def parse_amount(text: str, option: str, words: tuple[str, ...]):
    """``--observe`` / ``--observe-frames``: a fraction of each motion's valid steps, written
    ``0.25`` (with a decimal point or an exponent) or ``25%``, or one of ``words``. A whole number
    (``25``) is refused: steps go in ``OPTION-steps``. One line naming ``option`` otherwise."""
    text = text.strip()
    if text in words:
        return text
    percent = text.endswith("%")
    number = text[:-1].strip() if percent else text
    try:
        value = float(number)
    except ValueError:
        allowed = " or ".join(repr(w) for w in words)
        raise UserError(
            f"{option} {text!r}: give a fraction with a decimal point (0.25), a percentage (25%) or {allowed} "
            f"(a number of steps: {option}-steps 10)"
        ) from None
    if not percent and not any(c in number for c in ".eE"):
        raise UserError(
            f"{option} {text}: write {text}% for a percentage of each motion or {option}-steps {text} for "
            f"{text} steps (a fraction has a decimal point: 0.25)"
        )
    fraction = value / 100 if percent else value
    if not (math.isfinite(fraction) and 0 < fraction <= 1):
        raise UserError(f"{option} {text}: the observed fraction must be in (0, 1] (above 0 % and at most 100 %)")
    return fraction


def observed_amount(text: str | None, steps: int | None, option: str, words: tuple[str, ...]):
    """``OPTION`` (:func:`parse_amount`) or ``OPTION-steps`` (a number of steps, at least 1), not both;
    None when neither is given."""
    if steps is None:
        return None if text is None else parse_amount(text, option, words)
    if text is not None:
        raise UserError(f"give {option} {text} or {option}-steps {steps}, not both")
    if steps < 1:
        raise UserError(f"{option}-steps {steps}: observe at least 1 step (or {option} none)")
    return int(steps)


def observed_text(observation: dict, frames: bool) -> str:
    """An observation rule (``{"motor": 0.25, "frames": 0.25}``) in words: ``the first 25 % of the
    joints`` (and of the frames, for data with frames)."""

    def amount(value) -> str:
        if value == "none":
            return "none"
        if value == "first":
            return "the first step"
        return f"the first {100 * value:g} %" if isinstance(value, float) else f"the first {value} step(s)"

    text = f"{amount(observation['motor'])} of the joints"
    if frames and observation.get("frames") is not None:
        text += f" and {amount(observation['frames'])} of the frames"
    return text
