"""The README is a front page a newcomer reads (≤ 150 lines) and every document is found from the index."""

from __future__ import annotations

import re

from conftest import REPO


def test_the_readme_is_short_and_keeps_the_set_up_and_test_command():
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 150
    for marker in ("<!-- run-command -->", "<!-- test-command -->", "## Exit codes", "HAL", "HPL", "P_MD"):
        assert marker in text, marker
    assert "docs/README.md" in text


def test_every_document_is_in_the_index_and_every_link_resolves():
    index = (REPO / "docs" / "README.md").read_text(encoding="utf-8")
    linked = set(re.findall(r"\]\(([^)#]+)", index))
    for doc in (REPO / "docs").glob("*.md"):
        if doc.name != "README.md":
            assert doc.name in linked, f"docs/{doc.name} is not in docs/README.md"
    for target in linked:
        assert (REPO / "docs" / target).resolve().exists(), target
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    for target in re.findall(r"\]\(([^)#]+)", readme):
        assert (REPO / target).exists(), target
