"""The documentation holds together: every page mkdocs.yml names exists, every page links to files that
exist, and every `motorid <command>` the README names is a command of the parser."""

import re
from pathlib import Path

from motorid.cli import COMMANDS, build_parser

REPO = Path(__file__).resolve().parents[1]


def _nav_pages() -> list[str]:
    text = (REPO / "mkdocs.yml").read_text()
    return re.findall(r"^\s*-\s*[^:\n]+:\s*(\S+\.md)\s*$", text, flags=re.M)


def test_every_page_in_mkdocs_exists_and_every_docs_page_is_in_it():
    pages = _nav_pages()
    assert "index.md" in pages and len(pages) >= 6
    missing = [p for p in pages if not (REPO / "docs" / p).is_file()]
    assert not missing, f"mkdocs.yml names pages that docs/ lacks: {missing}"
    unlisted = sorted(p.name for p in (REPO / "docs").glob("*.md") if p.name not in pages)
    assert not unlisted, f"docs pages not in mkdocs.yml nav: {unlisted}"


def test_links_in_readme_and_docs_point_to_files():
    broken = []
    for page in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]:
        for target in re.findall(r"\]\(([^)#\s]+)\)", page.read_text()):
            if not re.match(r"[a-z]+://", target) and not (page.parent / target).exists():
                broken.append(f"{page.relative_to(REPO)}: {target}")
    assert not broken, broken


def test_every_command_the_readme_names_exists():
    parser = build_parser()
    commands = set(next(a for a in parser._actions if a.dest == "command").choices)
    assert len(commands) == len(COMMANDS)
    named = set(re.findall(r"\bmotorid ([a-z][a-z-]+)", (REPO / "README.md").read_text()))
    assert {"fit", "diagnose", "simulate", "report", "plan"} <= named
    assert named <= commands, f"README names commands the parser lacks: {sorted(named - commands)}"
