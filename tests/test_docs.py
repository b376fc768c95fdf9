"""The manual holds together: every relative link and anchor resolves, and it speaks of sasmi alone."""
from __future__ import annotations

import re

import pytest

from conftest import REPO

PAGES = [REPO / "README.md", REPO / "CHANGELOG.md", *sorted((REPO / "docs").glob("*.md"))]
LINK = re.compile(r"\]\(([^)\s]+)\)")
# words of a lab notebook: the making of the project, not the product
DIARY = re.compile(r"\bsessions?\b|\bthe VM\b|(?-i:runs/fit[A-Z0-9])|history\.md|\bissue \d|\bissue's\b|"
                   r"\b(twenty|nineteenth|eighteenth)\b|/tmp/", re.IGNORECASE)


def _anchors(path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces to hyphens."""
    heads = re.findall(r"^#+\s+(.*)$", path.read_text(), re.MULTILINE)
    return {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-") for h in heads}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_relative_link_resolves(page):
    broken = []
    for target in LINK.findall(page.read_text()):
        if re.match(r"[a-z]+:", target):
            continue  # a web address
        file, _, anchor = target.partition("#")
        path = (page.parent / file).resolve() if file else page
        if not path.exists():
            broken.append(target)
        elif anchor and path.suffix == ".md" and anchor not in _anchors(path):
            broken.append(target)
    assert not broken, f"{page.name}: {broken}"


@pytest.mark.parametrize("page", [*PAGES, *sorted((REPO / "scenes").glob("*.toml")),
                                  *sorted((REPO / "gan" / "recipes").glob("*.toml"))], ids=lambda p: p.name)
def test_the_manual_speaks_of_sasmi_not_of_its_making(page):
    hits = [line.strip() for line in page.read_text().splitlines() if DIARY.search(line)]
    assert not hits, f"{page.name}: {hits}"
