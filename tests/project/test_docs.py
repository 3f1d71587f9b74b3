"""README.md and the docs/ pages link only to files of the repository that exist, and nothing a user reads
cites the developers' notes outside it."""
import re

import pytest

from builders import REPO_ROOT

REPO = REPO_ROOT
# not the build's copies under docs/_build
PAGES = [REPO / "README.md", *sorted(p for p in (REPO / "docs").rglob("*.md")
                                       if "_build" not in p.relative_to(REPO / "docs").parts)]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_resolves(page):
    if not page.exists():
        pytest.skip("the docs are not beside the tests (an installed package)")
    text = page.read_text(encoding="utf-8")
    text = re.sub(r"```.*?```", "", text, flags=re.S)            # code blocks hold commands, not links
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue
        path = target.split("#", 1)[0]
        if not (page.parent / path).exists():
            broken.append(target)
    assert broken == []


def test_nothing_a_user_reads_cites_files_outside_the_repository():
    if not (REPO / "docs").is_dir():
        pytest.skip("the docs are not beside the tests (an installed package)")
    files = [*PAGES, *(REPO / "notebooks").rglob("*.ipynb"), *(REPO / "locbook").rglob("*.py"),
             *(REPO / "locbook").rglob("*.csv")]
    cited = [str(f.relative_to(REPO)) for f in files
             if re.search(r"shared/notes|\bnote 00\d\b", f.read_text(encoding="utf-8", errors="replace"))]
    assert cited == []
