"""Every relative link in README.md and docs/*.md names a file that exists (and, for a markdown
page with a #fragment, a heading of that page); the solver-table markers are where `--readme`
is told to look."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^\s*```")


def _prose(text: str) -> str:
    """The page without its fenced code blocks (a `[x](y)` inside code is not a link)."""
    out, inside = [], False
    for line in text.splitlines():
        if FENCE.match(line):
            inside = not inside
            continue
        if not inside:
            out.append(line)
    return "\n".join(out)


def links(text: str) -> list[str]:
    return LINK.findall(_prose(text))


def anchors(text: str) -> set[str]:
    """GitHub's heading ids: lower case, punctuation dropped, spaces to hyphens, repeats numbered."""
    seen: dict[str, int] = {}
    out = set()
    for line in _prose(text).splitlines():
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        slug = re.sub(r"[^\w\- ]", "", m.group(1).strip().lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def broken_links(page: Path) -> list[str]:
    """The relative links of one page whose file (or heading) does not exist."""
    bad = []
    for target in links(page.read_text()):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):  # http:, https:, mailto:
            continue
        path, _, fragment = target.partition("#")
        file = page if not path else (page.parent / path).resolve()
        if not file.exists():
            bad.append(f"{target}: no such file")
        elif fragment and file.suffix == ".md" and fragment not in anchors(file.read_text()):
            bad.append(f"{target}: no heading #{fragment} in {file.name}")
    return bad


@pytest.mark.parametrize("page", PAGES, ids=[p.relative_to(ROOT).as_posix() for p in PAGES])
def test_relative_links_resolve(page):
    assert broken_links(page) == []


def test_a_broken_link_is_found(tmp_path):
    (tmp_path / "there.md").write_text("# A heading\n")
    page = tmp_path / "page.md"
    page.write_text("[ok](there.md) [ok](there.md#a-heading) [web](https://example.org/x) [self](#title)\n"
                    "# Title\n```\n[in code](nowhere.md)\n```\n"
                    "[gone](missing.md) [bad anchor](there.md#no-such)\n")
    assert broken_links(page) == ["missing.md: no such file", "there.md#no-such: no heading #no-such in there.md"]


def test_readme_links_every_docs_page():
    readme = links((ROOT / "README.md").read_text())
    assert [p.name for p in PAGES[1:] if f"docs/{p.name}" not in readme] == []


def test_solver_table_markers_are_on_the_page_the_help_names():
    from adcpdyn.benchmarks.solvers import README_BEGIN, README_END

    lines = (ROOT / "docs" / "benchmarks.md").read_text().splitlines()
    assert lines.count(README_BEGIN) == 1 and lines.count(README_END) == 1
    assert lines.index(README_BEGIN) < lines.index(README_END)
    assert "docs/benchmarks.md" in README_BEGIN
