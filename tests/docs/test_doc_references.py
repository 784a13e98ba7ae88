"""Every section the code and the documents point to by name exists where they say it is.

Code and documents name a section of a document as `(README, "Planned views")`, `README's "Benchmark"`,
`(docs/DETECTOR.md, "Foot point")` or, within one document, `"Operating point" below`. Such a name
must begin a heading or a paragraph's bold lead (`**Spinning inference threads (...).**`) of that
document, so that moving a section, or renaming it, cannot leave a pointer to nothing.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# `FILE`, then optionally 's and a comma, and optionally one section word (`README, Benchmark,
# "Spinning ..."`), then the quoted name; line breaks, indents and comment marks are folded first.
_NAMED = re.compile(
    r"(?<![\w/.`])(README|docs/[A-Z_]+\.md|MODEL_CARD)(?:\.md)?(?:'s)?,?"
    r"(?:\s+[A-Z][\w-]*(?:\s+[a-z]+)*,)?\s+\"([^\"]{3,100})\"")
_HERE = re.compile(r"\"([A-Z][^\"]{2,100})\" (?:below|above)\b")
_DOCUMENTS = {"README": "README.md", "MODEL_CARD": "models/MODEL_CARD.md"}


def _tracked(*patterns: str) -> list[Path]:
    listed = subprocess.run(["git", "ls-files", *patterns], cwd=ROOT, capture_output=True, text=True,
                            check=True).stdout.split()
    return [ROOT / name for name in listed]


def _fold(text: str) -> str:
    return re.sub(r"\s*\n\s*(?:#+\s+|\*\s+|//\s*)?", " ", text)


def _sections(document: Path) -> list[str]:
    """The headings and the bold paragraph leads of a Markdown document, outside code blocks."""
    names: list[str] = []
    fenced = False
    for line in document.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced:
            heading = re.match(r"#{1,6} (.+)", line)
            if heading:
                names.append(heading.group(1).strip())
            names += re.findall(r"^\*\*(.+?)\*\*", line)
    return names


def _key(name: str) -> str:
    return re.sub(r"(?:\s*\.\.\.|…)$", "", name).rstrip(". ")


def _missing(document: Path, names: list[tuple[str, str]]) -> list[str]:
    sections = _sections(document)
    return [f"{where}: {document.relative_to(ROOT)} has no section {name!r}"
            for where, name in names if not any(s.startswith(_key(name)) for s in sections)]


def _references() -> dict[Path, list[tuple[str, str]]]:
    wanted: dict[Path, list[tuple[str, str]]] = {}
    for path in _tracked("*.py", "*.md", "*.yaml", "*.yml", "*.toml", "*.html", "*.js"):
        if not path.is_file() or path == Path(__file__).resolve():  # its examples name no section
            continue
        text = _fold(path.read_text(encoding="utf-8", errors="replace"))
        where = str(path.relative_to(ROOT))
        for document, name in _NAMED.findall(text):
            target = ROOT / _DOCUMENTS.get(document, document)
            wanted.setdefault(target, []).append((where, name))
        if path.suffix == ".md":
            wanted.setdefault(path, []).extend((where, name) for name in _HERE.findall(text))
    return wanted


def test_every_named_section_exists() -> None:
    wanted = _references()
    assert sum(len(names) for names in wanted.values()) > 20  # the pattern still finds the pointers
    missing = [line for document, names in sorted(wanted.items())
               for line in (_missing(document, names) if document.is_file()
                            else [f"{names[0][0]}: no document {document.relative_to(ROOT)}"])]
    assert not missing, "\n".join(missing)


@pytest.mark.parametrize(("text", "found"), [
    ('see (README, "Planned views") for', [("README", "Planned views")]),
    ("(README, Benchmark,\n    # \"Spinning inference threads\")",
     [("README", "Spinning inference threads")]),
    ('the README\'s "Post-processing designs" figures', [("README", "Post-processing designs")]),
    ('(docs/DETECTOR.md, "Foot point")', [("docs/DETECTOR.md", "Foot point")]),
    ('the README\'s curl example "as sent"', []),
    ('samples/README.md, "x y z"', []),
])
def test_the_pattern_reads_the_ways_a_section_is_named(text: str, found: list[tuple[str, str]]) -> None:
    assert _NAMED.findall(_fold(text)) == found


def test_a_missing_section_is_reported(tmp_path: Path) -> None:
    document = ROOT / "README.md"
    assert _missing(document, [("x.py", "Benchmark"), ("x.py", "The nadir view ...")]) == [
        "x.py: README.md has no section 'The nadir view ...'"]
