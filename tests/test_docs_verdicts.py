"""No hand-typed verdict in docs/results.md (issue 42, item 5): the verdicts on the paper's
sentences are written by ``python -m primspace.report.markdown`` between the generated
markers; the prose around them may name the verdict words (the rules define "partly") but
never gives one, in the forms the claims table uses ("holds in every seed", "partly in 2",
"does not hold in any seed", "seed 0: holds", "v1: partly", a bold or bracketed verdict)."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
GENERATED = re.compile(r"<!-- generated: (?P<name>[\w-]+) -->.*?<!-- end generated: (?P=name) -->", re.S)
VERDICT = r"(?:holds|does not hold|partly)"
#: How a verdict reads when it is given (the claims table's forms), not when a rule is defined.
GIVEN = [
    re.compile(rf"\b{VERDICT}\s+in\s+(?:every|any|all|no|\d+|seeds?\b)", re.I),  # holds in every seed, partly in 2
    re.compile(rf"(?:\bseed\s+\d+|\bv\d+|\brule)\s*:\s*{VERDICT}\b", re.I),  # seed 0: holds, v1: partly
    re.compile(rf"\*\*\s*{VERDICT}\b", re.I),  # **holds ...
    re.compile(rf"\(\s*{VERDICT}\s*[),;]", re.I),  # (holds), (partly; ...
    re.compile(rf"\bverdicts?\b\W+(?:\w+\W+){{0,3}}{VERDICT}\b", re.I),  # verdict: holds, the verdict is partly
]


def prose(text: str) -> str:
    """``text`` with every generated block blanked (its lines kept, so line numbers hold)."""
    return GENERATED.sub(lambda m: "\n" * m.group(0).count("\n"), text)


def hand_typed_verdicts(text: str) -> list[str]:
    """``line N: text`` of each line of the prose that gives a verdict."""
    return [
        f"line {n}: {line.strip()}"
        for n, line in enumerate(prose(text).splitlines(), 1)
        if any(p.search(line) for p in GIVEN)
    ]


def test_docs_results_gives_no_verdict_outside_the_generated_blocks():
    text = (ROOT / "docs" / "results.md").read_text(encoding="utf-8")
    assert GENERATED.search(text), "docs/results.md has no generated block"
    found = hand_typed_verdicts(text)
    assert not found, "hand-typed verdicts in docs/results.md (generate them instead):\n" + "\n".join(found)


@pytest.mark.parametrize(
    "line",
    [
        "- **LASA.** The second sentence holds in every seed (3 of 3).",
        "the earlier rule (v1: holds) stands beside it",
        "On the demo the claim is **partly** met.",
        "seed 0: does not hold, seed 1: holds",
        "zero and projection cluster alike (partly).",
        "the verdict is partly, as before",
        "does not hold in any seed",
    ],
)
def test_a_hand_typed_verdict_is_caught(line):
    assert hand_typed_verdicts(f"intro\n\n{line}\n")


def test_prose_that_defines_the_words_or_lies_in_a_block_passes():
    text = (
        'a sentence that half holds is "partly"; a comparison holds only when the difference exceeds its spread\n'
        "the structure is there before training and is partly kept by it\n"
        "<!-- generated: results -->\n| claim | **holds in every seed (3 of 3)** (seed 0: holds) |\n"
        "<!-- end generated: results -->\n"
    )
    assert hand_typed_verdicts(text) == []
