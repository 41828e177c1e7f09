"""CI: summarize the per-test durations of a pytest JUnit XML file.

Usage: python .ci/durations.py JUNIT_XML FULL_LIST_TXT
Writes every test's time (set-up + call + tear-down), slowest first, to FULL_LIST_TXT, and
prints the total (what the tests would take in one process) and the ten slowest modules.
"""

import sys
import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path

junit, full = Path(sys.argv[1]), Path(sys.argv[2])
tests = []
for case in ET.parse(junit).iter("testcase"):
    module = case.get("classname", "").replace(".", "/") + ".py"
    tests.append((float(case.get("time", 0)), f"{module}::{case.get('name')}"))
tests.sort(reverse=True)
full.write_text("".join(f"{t:9.2f}s {name}\n" for t, name in tests), encoding="utf-8")
by_module = Counter()
for t, name in tests:
    by_module[name.split("::")[0]] += t
total = sum(t for t, _ in tests)
print(f"test durations: {len(tests)} tests, {total:.0f} s in all (one process's time), every test in {full}")
print("slowest modules: " + ", ".join(f"{m.removeprefix('tests/')} {t:.0f} s" for m, t in by_module.most_common(10)))
