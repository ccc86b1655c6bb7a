"""The docs stay true to their sources: the generated pages match what generates them, a
quantity of the current figures is quoted nowhere else, every config key is explained, and
the pages stay short enough to read. (`make docs` checks every internal link and anchor.)"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import pytest

from rodphase import config, store, studytools

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
CURRENT = json.loads((DOCS / "current.json").read_text())


def current_pages() -> list[Path]:
    """README and every page of the docs but the history and the current figures."""
    pages = [ROOT / "README.md"] + sorted(DOCS.rglob("*.md"))
    return [p for p in pages if "history" not in p.relative_to(ROOT).parts
            and p != DOCS / "current.md"]


def test_current_figures_page_is_rendered_from_its_json():
    # a stale page: run `python -c "from rodphase.studytools import write_current_pages;
    # write_current_pages()"` (the measuring scripts do it when they record a value)
    assert (DOCS / "current.md").read_text() == studytools.render_current(CURRENT)
    assert (DOCS / "history" / "figures.md").read_text() == \
        studytools.render_figure_history(CURRENT)


def test_generated_figures_are_the_ones_recorded():
    # the figure `make current-fig3` drew with the labels it recorded, not another one
    for key, entry in CURRENT["quantities"].items():
        figure = entry.get("figure")
        if figure:
            digest = hashlib.sha256((DOCS / figure["path"]).read_bytes()).hexdigest()
            assert digest == figure["sha256"], f"{figure['path']} is not the figure of {key}"


def _figures(value: str) -> set[str]:
    """The measured numbers of a value with their units ("93.6 s", "12.49 µs", "743 s")."""
    return set(re.findall(r"\d+(?:\.\d+)? ?(?:s\b|µs|M steps|min\b)", value))


def test_each_current_figure_is_quoted_only_on_the_current_page():
    # a table between <!-- name:begin --> and <!-- name:end --> is the measuring script's own
    # output, written by it (rodphase.studytools.write_block): not a copy
    quoted = {}
    for page in current_pages():
        text = re.sub(r"<!-- (\S+):begin -->.*?<!-- \1:end -->", "", page.read_text(),
                      flags=re.S)
        for key, entry in CURRENT["quantities"].items():
            for figure in _figures(entry["value"]):
                if re.search(rf"(?<![\d.]){re.escape(figure)}", text):
                    quoted.setdefault(figure, []).append(page.relative_to(ROOT).as_posix())
    assert not quoted, f"current figures quoted outside docs/current.md: {quoted}"


def test_every_config_key_has_a_meaning():
    keys = {f"{section}.{key}" for section, fields in config.SCENE_SCHEMA.items()
            for key in fields} | {f"sweep.{key}" for key in config.SWEEP_SCHEMA}
    assert keys == set(config.MEANINGS)


def test_reference_pages_are_rendered_from_the_code():
    # stale: run `python docs/gen_reference.py` and commit docs/reference/
    import runpy

    generator = runpy.run_path(str(DOCS / "gen_reference.py"), run_name="gen_reference")
    assert generator["stale"]() == []


def test_data_format_page_names_the_format_version():
    page = (DOCS / "reference" / "data-format.md").read_text()
    assert f"| `format_version` | int | `{store.FORMAT_VERSION}` for files written now" in page


@pytest.mark.parametrize("page", current_pages(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_pages_outside_the_history_are_short(page):
    limit = 120 if page.name == "README.md" else 400
    assert len(page.read_text().splitlines()) <= limit


def test_readme_links_resolve():
    text = (ROOT / "README.md").read_text()
    for target in re.findall(r"\]\(([^)#\s]+)[^)]*\)", text):
        if not target.startswith("http"):
            assert (ROOT / target).exists(), target
