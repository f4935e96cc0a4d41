"""What the docstrings, comments and documents cite is in the repository.

A citation of a file that is not there (the old design reference, a module after a
move) sends a reader nowhere, so:

* in ``.py`` docstrings and comments, a path that starts at one of the repository's
  top-level entries (``edge_runtime/robot/hazard.py``, ``docs/design.md``) exists; a
  bare markdown file name is at the root, beside the citing file or in ``docs/``,
  unless the citing module writes a file of that name itself (a report it makes);
  the old reference's informal name (in capitals, then "section N") is gone too;
* "``docs/design.md`` section N" needs a heading numbered N there (so does any cited
  markdown file);
* in ``.md`` files, every relative link target exists.
"""
from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from pathlib import Path

import pytest
from support import REPO_ROOT
from support.source import NOT_SOURCE, docstrings_and_comments, repo_files

CITATION = re.compile(
    r"(?<![\w/.:~$@-])(?P<path>(?:[\w.-]+/)+[\w.-]*|[\w.-]+\.md\b)(?:,?\s+section\s+(?P<section>\d+))?"
    r"|\bDESIGN(?=\s+section\b)")
"""A path with a folder or a bare markdown file name, optionally followed by "section N"; or
the design reference's informal name as some docstrings cited it."""
MD_LINK = re.compile(r"!?\[[^\]]*\]\((?P<target>[^)\s]+)\)")
PLACEHOLDER = re.compile(r"^[A-Z][A-Z0-9_]*$")
"""A path segment like DIR, OUT or SOMEDIR stands for the reader's own folder."""


@dataclass(frozen=True)
class Citation:
    where: str
    """``file:line`` of the citing text."""
    cited: str
    why: str

    def __str__(self) -> str:
        return f"{self.where}: cites {self.cited}: {self.why}"


def _numbered_sections(md: Path) -> set[str]:
    return set(re.findall(r"^#+\s+(\d+)\.", md.read_text(encoding="utf-8"), re.M))


def _written_names(path: Path) -> set[str]:
    """File names the module itself writes or names as output: its string literals ending in .md."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return {Path(n.value).name for n in ast.walk(tree)
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and n.value.endswith(".md")
            and not any(c.isspace() for c in n.value)}


def _check_section(root: Path, md: Path, section: str | None) -> str | None:
    if section is not None and md.suffix == ".md" and section not in _numbered_sections(md):
        return f"{md.relative_to(root)} has no section {section}"
    return None


def broken_citations_in_py(root: Path, path: Path) -> list[Citation]:
    top_level = {p.name for p in root.iterdir() if p.name != ".git" and p.name not in NOT_SOURCE}
    rel = path.relative_to(root)
    written = _written_names(path)
    broken = []
    for line, text in docstrings_and_comments(path):
        for m in CITATION.finditer(text):
            where = f"{rel}:{line + text.count(chr(10), 0, m.start())}"
            cited = (m.group("path") or "DESIGN").rstrip("./")
            parts = cited.split("/")
            if cited == "DESIGN":
                if not (root / "DESIGN.md").exists():
                    broken.append(Citation(where, "DESIGN", "the old design reference is gone: cite docs/design.md"))
                continue
            if any(PLACEHOLDER.match(p) for p in parts[:-1]):
                continue
            if parts[0] in top_level:
                candidates = [root / cited]
            elif cited.endswith(".md") and parts[-1] not in written:
                candidates = [root / cited, path.parent / cited, root / "docs" / cited]
            else:
                continue  # not a repository path: a folder of the user's, a pair like "stop/retract"
            found = next((c for c in candidates if c.exists()), None)
            problem = (f"no such file ({' or '.join(str(c.relative_to(root)) for c in candidates)})" if found is None
                       else _check_section(root, found, m.group("section")))
            if problem:
                broken.append(Citation(where, cited, problem))
    return broken


def broken_links_in_md(root: Path, path: Path) -> list[Citation]:
    broken = []
    for line_no, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        for m in MD_LINK.finditer(line):
            target = m.group("target").split("#")[0]
            if not target or re.match(r"^[a-z][a-z0-9+.-]*:", target):
                continue  # an anchor in the same page, or a URL
            if not (path.parent / target).exists():
                broken.append(Citation(f"{path.relative_to(root)}:{line_no}", target, "no such file"))
    return broken


@pytest.mark.parametrize("suffix, check", [(".py", broken_citations_in_py), (".md", broken_links_in_md)],
                         ids=["py-docstrings-and-comments", "md-links"])
def test_cited_files_exist(suffix, check):
    files = repo_files(REPO_ROOT, suffix)
    assert files
    broken = [str(c) for f in files for c in check(REPO_ROOT, f)]
    assert not broken, "citations of files that are not in the repository:\n" + "\n".join(broken)


def test_design_notes_keep_their_section_numbers():
    """Code cites docs/design.md by section number: the numbers must not move."""
    assert {"2", "5", "6", "7", "8"} <= _numbered_sections(REPO_ROOT / "docs" / "design.md")


def test_the_checks_catch_broken_citations(tmp_path):
    """Planted citations: each broken one is reported with its file and line, the sound ones are not."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "notes.md").write_text("# Notes\n\n## 3. Three\n\nSee [gone](../missing.md) and "
                                                "[here](notes.md#3-three), [web](https://example.org/x.md).\n")
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "real.py").write_text("")
    (pkg / "mod.py").write_text(
        '"""Cites docs/notes.md section 3, pkg/real.py and\ndocs/notes.md section 4."""\n'
        "# see pkg/gone.py and OLD.md; DIR/report.md is the user's; DESIGN section 8\n"
        'OUT = "report.md"\n'
        "def f():\n"
        '    """Writes report.md; reads README.md (no such file either)."""\n')
    found = {(c.where, c.cited) for c in broken_citations_in_py(tmp_path, pkg / "mod.py")}
    assert found == {("pkg/mod.py:2", "docs/notes.md"), ("pkg/mod.py:3", "pkg/gone.py"),
                     ("pkg/mod.py:3", "OLD.md"), ("pkg/mod.py:3", "DESIGN"), ("pkg/mod.py:6", "README.md")}
    links = broken_links_in_md(tmp_path, tmp_path / "docs" / "notes.md")
    assert [(c.where, c.cited) for c in links] == [("docs/notes.md:5", "../missing.md")]
