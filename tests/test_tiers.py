"""The two test tiers of the Makefile partition the suite: `make test` (the tests that guard
what a user runs) and `make test-slow` (the long tier that `make test-all` and CI add) together
run every test that pytest collects, and no test runs in both. A tier's marker expression or
an option added to one target (a -k, an --ignore, a path) that drops a test fails here."""

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _pytest_options(target: str) -> list[str]:
    """The options the Makefile's `target` passes to pytest (its one pytest line)."""
    text = (ROOT / "Makefile").read_text()
    recipe = re.search(rf"^{re.escape(target)}:.*\n((?:\t.*\n)+)", text, re.MULTILINE)
    assert recipe, f"no target {target} in the Makefile"
    lines = [line for line in recipe.group(1).splitlines() if "/pytest" in line]
    assert len(lines) == 1, f"{target}: one pytest line expected, got {lines}"
    words = shlex.split(lines[0].strip())
    return words[1:]


# one process collects the suite once and selects each tier from it (pytest.main again in
# the same process reuses the imported test modules: one collection's time, not three)
COLLECT = r"""
import json, sys
import pytest

class Selected:
    ids = None

    def pytest_collection_finish(self, session):
        self.ids = [item.nodeid for item in session.items]

found = []
for options in json.loads(sys.argv[1]):
    selected = Selected()
    code = pytest.main(["--collect-only", "-qq", "-p", "no:xdist", "-p", "no:cacheprovider",
                        *options], plugins=[selected])
    found.append({"code": int(code), "ids": selected.ids})
with open(sys.argv[2], "w") as out:
    json.dump(found, out)
"""


def _collected(selections: list[list[str]], tmp_path) -> list[set[str]]:
    """The node ids pytest selects with each of `selections` (lists of options)."""
    out = tmp_path / "collected.json"
    done = subprocess.run([sys.executable, "-c", COLLECT, json.dumps(selections), str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    found = json.loads(out.read_text())
    for options, one in zip(selections, found):
        assert one["code"] == 0, (options, done.stdout[-3000:])
    return [set(one["ids"]) for one in found]


def _without_xdist(options: list[str]) -> list[str]:
    """`options` less the workers and the verbosity: the same selection of tests."""
    kept, skip = [], False
    for word in options:
        if skip:
            skip = False
            continue
        if word in ("-n", "--numprocesses", "--dist", "--maxprocesses"):
            skip = True
            continue
        # -n4, --dist=load; and the verbosity, which would change what --collect-only prints
        if word.startswith(("-n", "--numprocesses=", "--dist=", "--maxprocesses=", "-q", "-v")):
            continue
        kept.append(word)
    return kept


def test_the_fast_and_slow_tiers_partition_the_suite(tmp_path):
    fast, slow, everything = _collected([_without_xdist(_pytest_options("test")),
                                         _without_xdist(_pytest_options("test-slow")), []],
                                        tmp_path)
    assert len(everything) > 500  # the suite itself was collected, not an empty selection
    assert fast and slow
    assert not fast & slow, sorted(fast & slow)[:20]
    assert fast | slow == everything, sorted(everything - (fast | slow))[:20]


def test_ci_runs_both_tiers():
    words = (ROOT / ".ci" / "run").read_text()
    assert re.search(r"^make test( |$)", words, re.MULTILINE)
    assert re.search(r"^make test-slow( |$)", words, re.MULTILINE)
    all_recipe = re.search(r"^test-all:(.*)$", (ROOT / "Makefile").read_text(), re.MULTILINE)
    assert all_recipe and {"test", "test-slow"} <= set(all_recipe.group(1).split("##")[0].split())
