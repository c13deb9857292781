"""Every documentation link resolves: in README.md and docs/*.md, each relative Markdown link
([text](path#anchor)) names a file that exists and, with an anchor, a heading of that file (as
GitHub makes anchors); in those files and in the Python package's docstrings and the binding's
comments (python/flatland/*.py, *.pyi, python/src/), each mention of a document (docs/NAME.md,
NAME.md#anchor, or NAME.md "Section" / NAME.md, "Section") names one that exists, and the anchor
or section one of its headings."""

import re
from functools import lru_cache
from pathlib import Path

import pytest

from conftest import ROOT

DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SOURCES = [*sorted((ROOT / "python" / "flatland").glob("*.py")),
           *sorted((ROOT / "python" / "flatland").glob("*.pyi")),
           *sorted((ROOT / "python" / "src").glob("*.[ch]pp"))]

MARKDOWN_LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
# A document named in prose: docs/NAME.md or NAME.md (upper-case names: the project's documents),
# with an optional #anchor, or a quoted section after it ("NAME.md "Section"", "NAME.md, "S"").
MENTION = re.compile(r"(?<![\w/.-])((?:docs/)?[A-Z][A-Z_]*\.md)(#[\w-]+)?(?:,? \"([^\"]+)\")?")


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, markup and punctuation dropped, spaces to -."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip()).lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


@lru_cache(maxsize=None)
def headings(path: Path):
    """(anchors, heading texts) of a Markdown file, outside fenced code."""
    anchors, texts, counts, fenced = set(), [], {}, False
    for line in path.read_text().splitlines():
        if line.startswith("```"):
            fenced = not fenced
            continue
        if fenced:
            continue
        label = re.match(r"\*\*([^*]+?)\.?\*\*", line)  # a paragraph's bold label: a section too
        if label:
            texts.append(label.group(1))
        m = re.match(r"#{1,6} (.+)", line)
        if not m:
            continue
        base = slug(m.group(1))
        n = counts.get(base, 0)
        counts[base] = n + 1
        anchors.add(base if n == 0 else f"{base}-{n}")
        texts.append(re.sub(r"[`*]", "", m.group(1)))
    return anchors, texts


def strip_code_blocks(text: str) -> str:
    return re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)


def resolve_mention(name: str, origin: Path) -> Path:
    if name.startswith("docs/"):
        return ROOT / name
    for base in (origin.parent, ROOT / "docs", ROOT):
        if (base / name).is_file():
            return base / name
    return ROOT / "docs" / name


def problems_of(path: Path):
    text = path.read_text()
    found = []
    prose = strip_code_blocks(text) if path.suffix == ".md" else text
    if path.suffix == ".md":
        for target in MARKDOWN_LINK.findall(prose):
            if re.match(r"[a-z]+:", target):  # https:, mailto:
                continue
            file, _, anchor = target.partition("#")
            doc = (path.parent / file).resolve() if file else path
            if not doc.exists():
                found.append(f"{target}: no file {doc}")
            elif anchor and doc.suffix == ".md" and anchor not in headings(doc)[0]:
                found.append(f"{target}: no heading #{anchor} in {doc.name}")
    # Mentions in prose; a Markdown link's target was checked above.
    for name, anchor, section in MENTION.findall(re.sub(r"\]\([^)\s]+\)", "]", prose)):
        doc = resolve_mention(name, path)
        if not doc.is_file():
            found.append(f"{name}: no such document")
            continue
        anchors, texts = headings(doc)
        if anchor and anchor[1:] not in anchors:
            found.append(f"{name}{anchor}: no such heading in {doc.name}")
        if section and not any(section.lower() in t.lower() for t in texts):
            found.append(f'{name} "{section}": no such section in {doc.name}')
    return found


@pytest.mark.parametrize("path", DOCS + SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_link_resolves(path):
    assert problems_of(path) == []


def test_the_checker_catches_broken_links(tmp_path):
    doc = tmp_path / "X.md"
    doc.write_text('# Top\n## A `b` c\n[ok](X.md#a-b-c) [bad](X.md#nope) [gone](Y.md)\n'
                   'X.md "Top" X.md, "Nowhere" NOWHERE.md\n')
    assert sorted(problems_of(doc)) == sorted([
        "X.md#nope: no heading #nope in X.md", f"Y.md: no file {tmp_path / 'Y.md'}",
        'X.md "Nowhere": no such section in X.md', "NOWHERE.md: no such document"])
