"""The paper pages as a reader meets them: the citation and what the paper claims first, then
the verdicts, the paper's figures, the single runs and the notes; every table row with its
header's cells; numbers in fixed notation. Read from the committed pages
(``tests/test_docs_site.py::test_generated_pages_are_current`` keeps them the tree's)."""

from __future__ import annotations

import re
from pathlib import Path

import markdown
import pytest
from claim_rows import claim_row

from cosim.reproduce.entry import entry_names, load_entry
from cosim.reproduce.tables import md_row
from cosim.reproduce.verdicts import CLAIMS_HEADER, ClaimRow, by_origin, claims_markdown

PAPERS = Path(__file__).resolve().parent.parent / "docs" / "papers"
_CELL_SEP = re.compile(r"(?<!\\)\|")  # a cell border: a pipe not escaped


def _pages() -> list[str]:
    return [name for name in entry_names() if (PAPERS / f"{name}.md").is_file()
            and "<!-- inputs " in (PAPERS / f"{name}.md").read_text()]


def _tables(text: str) -> list[list[str]]:
    """The markdown tables of ``text``: each a list of its lines (header, rule, rows)."""
    tables: list[list[str]] = []
    previous = False
    for line in text.splitlines():
        row = line.startswith("|")
        if row and not previous:
            tables.append([])
        if row:
            tables[-1].append(line)
        previous = row
    return tables


def _cells(line: str) -> int:
    return len(_CELL_SEP.findall(line.strip())) - 1


@pytest.mark.parametrize("name", _pages())
def test_a_paper_page_reads_citation_verdicts_figures_runs_notes(name: str) -> None:
    """The page opens with the entry's title, citation (with its DOI or that the paper gives
    none) and summary; then the verdicts (their counts, the headline reading, the paper's
    claims that fail, how the page is reproduced, the statements); the sections follow in
    the reader's order."""
    entry = load_entry(name)
    text = (PAPERS / f"{name}.md").read_text()
    headings = re.findall(r"^(#{1,4}) (.+)$", text, re.M)
    assert headings[0] == ("#", entry.title)
    order = ["Verdicts", "The paper's figures, redrawn", "Single runs",
             "Where we differ from the paper, and why"]
    sections = [h for level, h in headings if level == "###"]
    present = [s for s in order if s in sections]
    assert present == [s for s in sections if s in order]  # in this order
    assert sections[:1] == present[:1] and "Single runs" in present
    opening = text[:text.index("### ")]
    assert entry.citation in opening and " ".join(entry.summary.split()) in opening
    doi = f"https://doi.org/{entry.doi}" if entry.doi else "DOI not given in the paper."
    assert doi in opening
    source = f"Reproduced by `cosim reproduce {name}`"
    if entry.claims:
        verdicts = re.search(r"^### Verdicts$(.*?)^### ", text, re.M | re.S).group(1)
        assert verdicts.lstrip().startswith("**Verdicts**")
        assert "**Headline**" in verdicts or not any(s.headline for s in entry.statements)
        assert "#### The paper's statements" in verdicts or not entry.statements
        lead = verdicts.split("#### ")[0]  # above the statements and the claims
        assert source in lead
        failing = re.findall(r"^- .* \(`(\w+)`\)$", lead, re.M)  # the list of failures
        paper = re.search(r"\d+ of the paper: ([^;.]*)", lead).group(1)  # the counts
        fails = re.search(r"(\d+) fails", paper)
        assert len(failing) == (int(fails.group(1)) if fails else 0), (paper, failing)
        for ident in failing:  # each a claims-table row that fails
            assert re.search(rf"^\| {ident}: [^\n]*\| fails \|", verdicts, re.M), ident
    else:
        assert source in opening


@pytest.mark.parametrize("name", _pages())
def test_each_svg_link_is_a_file_beside_the_page_and_each_svg_is_linked(name: str) -> None:
    """Every "SVG" link (under a figure: its vector drawing) names a file beside the page, and
    every svg beside the page (its record aside) is linked, right under its png where it has
    one."""
    text = (PAPERS / f"{name}.md").read_text()
    linked = re.findall(r"(?<!!)\[SVG\]\(([^)\s]+)\)", text)
    for target in linked:
        assert (PAPERS / target).is_file(), target
    beside = {p.relative_to(PAPERS).as_posix() for p in (PAPERS / name).rglob("*.svg")
              if "record" not in p.relative_to(PAPERS / name).parts}
    assert beside <= set(linked), sorted(beside - set(linked))
    for target in linked:
        png = target.removesuffix(".svg") + ".png"
        if (PAPERS / png).is_file():
            assert re.search(rf"!\[[^\]]*\]\({re.escape(png)}\)\s*\n\s*\n?"
                             rf"\[SVG\]\({re.escape(target)}\)", text), target


@pytest.mark.parametrize("name", _pages())
def test_every_table_row_has_its_headers_cells(name: str) -> None:
    """In the source and as the site's Markdown renders it (which pads a short row with an
    empty cell), every row of every table has as many cells as its header."""
    text = (PAPERS / f"{name}.md").read_text()
    tables = _tables(text)
    assert tables
    for table in tables:
        width = _cells(table[0])
        short = [line[:80] for line in table[1:] if _cells(line) != width]
        assert not short, (name, table[0][:80], short)
    claims = [t for t in tables if t[0] == md_row(list(CLAIMS_HEADER))]
    html = markdown.markdown("\n\n".join("\n".join(t) for t in claims), extensions=["tables"])
    for row in re.findall(r"<tr>(.*?)</tr>", html, re.S)[1:]:
        cells = re.findall(r"<td[^>]*>(.*?)</td>", row, re.S)
        assert len(cells) == len(CLAIMS_HEADER) and cells[-1].strip() in (
            "yes", "no", "untested", "-", "n/a"), (name, cells[:1])


@pytest.mark.parametrize("name", _pages())
def test_every_published_rounding_rerun_changes_a_value(name: str) -> None:
    """Each perturbed floating-point path of a published page changed a value a claim reads
    in some member (the page names a path that changed none: its entry perturbs nothing the
    runs use, a rerun that tests nothing)."""
    from cosim.reproduce.verdicts import IDLE_PATH

    assert IDLE_PATH not in (PAPERS / f"{name}.md").read_text(), name


@pytest.mark.parametrize("name", _pages())
def test_page_numbers_are_in_fixed_notation(name: str) -> None:
    """No number of ours on the page is printed in scientific notation."""
    text = (PAPERS / f"{name}.md").read_text()
    tables = "\n".join(line for line in text.splitlines() if line.startswith("|"))
    assert not re.findall(r"\d\.?\d*e[+-]\d\d", tables)


def _row(**change: object) -> ClaimRow:
    fields: dict[str, object] = {
        "median": -0.0001518, "ci_low": -0.0002, "ci_high": -0.00012, "b_median": 0.3,
        "paper": "5.95 cm", "source": "Table 1"}
    return claim_row(**(fields | change))


def test_claims_rows_keep_their_cells_and_group_by_origin() -> None:
    """A claim whose text or paper figure holds a pipe or a line break keeps the header's
    cells; the rows come the paper's first, then ours, then the sanity checks; the quantity
    is named by the metric's heading (its unit) and printed in one fixed notation."""
    rows = [_row(id="sanity_1", origin="sanity"), _row(id="ours_1", origin="ours"),
            _row(id="paper_1", text="max |e| below\nthe band", paper="0.132\nkm/h"),
            _row(id="paper_2", rounding_robust=None)]
    text = claims_markdown(rows, 20, headings={"stop_error_m": "stop error (m)"})
    table = _tables(text)[0]
    assert all(_cells(line) == len(CLAIMS_HEADER) for line in table)
    assert [line.split(":")[0].strip("| ") for line in table[2:]] == [
        "paper_1", "paper_2", "ours_1", "sanity_1"]
    assert [r.claim.id for r in by_origin(rows)] == ["paper_1", "paper_2", "ours_1", "sanity_1"]
    assert "A - B, stop error (m): -0.000152 [-0.000200, -0.000120] (-0.051 % of B)" in text
