"""The documentation site: generated pages current, the site builds with warnings as errors,
every runnable block of the docs runs, and (slow) the built pages render in a headless Chromium
as a reader sees them.

Convention for code blocks in ``docs/*.md``: a ```` ```bash ```` block is run by
:func:`test_bash_block_runs` in a fresh temporary folder, with this checkout's ``cosim`` first
on ``PATH``, and must exit 0 within ``BLOCK_TIMEOUT_S``; ```` ```python ```` blocks are executed
as scripts the same way. An HTML comment ``<!-- norun -->`` on the line right before the fence
marks a block shown only (installs, long runs), and ``<!-- slow -->`` a block that runs in the
slow suite only (``pytest -m slow``: one that builds or validates the whole catalog): the
comment is invisible in the rendered page, and the fence's info string stays one word, which
is all the site's Markdown (Python-Markdown with pymdownx.superfences) recognises;
```` ```bash norun ```` is not a fence there and swallows the text after it into a code box.
Other fences (toml, text, sh, c) are data or other languages.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from cosim import site
from cosim.cli import app, cli_reference

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
BLOCK_TIMEOUT_S = 1800  # a guard against a hang, not a speed check: the longest block builds and
# validates every native FMU, about 150 s of CPU on 2 cores unloaded (12x margin for a busy machine)
NORUN = "<!-- norun -->"  # on the line before a fence: the block is shown, not run
SLOW = "<!-- slow -->"  # on the line before a fence: the block runs in the slow suite only
_FENCE = re.compile(r"^(<!-- (?:norun|slow) -->\n)?```(bash|python)[ \t]*\n(.*?)^```[ \t]*$",
                    re.M | re.S)
_OPENING = re.compile(r"^[ \t]*```(.*)$", re.M)  # every fence line: opening or closing


def _blocks() -> list[Any]:
    """Every runnable block as (where, language, code), those marked :data:`SLOW` with the
    slow mark."""
    found = []
    for page in sorted(DOCS.rglob("*.md")):
        for i, m in enumerate(_FENCE.finditer(page.read_text())):
            if m.group(1) != NORUN + "\n":
                marks = pytest.mark.slow if m.group(1) == SLOW + "\n" else ()
                found.append(pytest.param(f"{page.relative_to(DOCS)}#{i}", m.group(2),
                                          m.group(3), marks=marks))
    return found


def test_fences_name_one_language() -> None:
    """Each fence's info string is one word (or none, a closing fence): superfences takes
    ```` ```bash norun ```` for text, and everything after it up to the next fence lands in a
    code box, out of the table of contents."""
    for page in sorted(DOCS.rglob("*.md")):
        for m in _OPENING.finditer(page.read_text()):
            assert re.fullmatch(r"[A-Za-z0-9_+-]*[ \t]*", m.group(1)), (page, m.group(0))


def test_norun_marks_only_the_block_after_it() -> None:
    page = f"a\n\n{NORUN}\n```bash\nexit 1\n```\n\n```bash\ntrue\n```\n"
    found = [(m.group(1), m.group(2), m.group(3)) for m in _FENCE.finditer(page)]
    assert found == [(NORUN + "\n", "bash", "exit 1\n"), (None, "bash", "true\n")]
    slow = [m.group(1) for m in _FENCE.finditer(f"{SLOW}\n```bash\ntrue\n```\n")]
    assert slow == [SLOW + "\n"]
    run = [block.values[2] for block in _blocks()]
    assert run and not any("pip install" in code for code in run)  # installs are shown only


def test_generated_pages_are_current() -> None:
    result = CliRunner().invoke(app, ["docs", "--check"])
    assert result.exit_code == 0, result.output


def test_check_names_a_stale_page(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text("old\n")
    assert site.stale(iter([(page, b"new\n")])) == [page]
    assert site.stale(iter([(page, b"old\n")])) == []
    assert site.stale(iter([(tmp_path / "missing.md", b"x")])) == [tmp_path / "missing.md"]


def test_cli_reference_lists_every_command_and_option() -> None:
    import typer

    text = cli_reference()
    group = typer.main.get_command(app)
    for name, cmd in group.commands.items():
        assert f"## cosim {name}\n" in text
        for param in cmd.params:
            for opt in getattr(param, "opts", []):
                if opt.startswith("--") and opt != "--help":
                    assert opt in text, (name, opt)


def test_paper_page_is_the_whole_table_else_the_claims_and_copies_figures(tmp_path: Path
                                                                           ) -> None:
    run = tmp_path / "seedX"
    (run / "fig").mkdir(parents=True)
    (run / "claims.md").write_text("## Claims\n\n![a](fig/a.png) [web](https://x.org/y.png)"
                                   "\n\n[SVG](fig/a.svg)\n")
    (run / "fig" / "a.png").write_bytes(b"PNG")
    (run / "fig" / "a.svg").write_bytes(b"<svg/>")
    page = site.paper_page("seedX", run)
    assert page is not None
    text = page[DOCS / "papers" / "seedX.md"].decode()
    assert text.count("# Claims") == 1
    assert "![a](seedX/fig/a.png)" in text and "(https://x.org/y.png)" in text
    assert "[SVG](seedX/fig/a.svg)" in text  # the vector figure linked and copied beside
    assert page[DOCS / "papers" / "seedX" / "fig" / "a.png"] == b"PNG"
    assert page[DOCS / "papers" / "seedX" / "fig" / "a.svg"] == b"<svg/>"
    (run / "table.md").write_text("## T\n\nthe table, claims, figures and notes\n")
    page = site.paper_page("seedX", run)
    assert b"the table, claims" in page[DOCS / "papers" / "seedX.md"]
    assert site.paper_page("seedY", tmp_path / "none") is None


def test_only_the_claims_table_is_marked_for_the_stylesheet() -> None:
    """A paper page's claims table, and no other table, renders inside the ``claims-table``
    div (md_in_html, as mkdocs.yml enables it) that the site's stylesheet fits to the page
    width; the text after it stays outside."""
    import markdown

    from cosim.reproduce.tables import md_row
    from cosim.reproduce.verdicts import CLAIMS_HEADER

    claims = [md_row(list(CLAIMS_HEADER)), "|" + " --- |" * len(CLAIMS_HEADER),
              md_row(["a_b: A stops first", "holds", "20 of 20", "0.1 [0, 0.2]", "-", "sec. 4",
                      "yes"])]
    text = "\n".join(["# P", "", "| x | y |", "| --- | --- |", "| 1 | 2 |", "", *claims, "",
                      "after", ""])
    html = markdown.markdown(site.mark_claims_tables(text),
                             extensions=["tables", "md_in_html"])
    assert html.count("<table>") == 2
    div = re.search(rf'<div class="{site.CLAIMS_CLASS}">(.*?)</div>', html, re.S)
    assert div and "<th>verdict</th>" in div.group(1) and "<td>a_b: A stops first</td>" \
        in div.group(1)
    assert "<td>1</td>" not in div.group(1) and "after" not in div.group(1)
    assert "<p>after</p>" in html
    config = (ROOT / "mkdocs.yml").read_text()
    assert "- md_in_html" in config and "- stylesheets/extra.css" in config
    assert f".{site.CLAIMS_CLASS} " in (DOCS / "stylesheets" / "extra.css").read_text()


def test_fill_generated_replaces_only_its_block() -> None:
    text = "a <!-- generated: k -->old<!-- end generated --> b"
    assert site.fill_generated(text, "k", "new") == (
        "a <!-- generated: k -->new<!-- end generated --> b")
    with pytest.raises(ValueError, match="generated: other"):
        site.fill_generated(text, "other", "x")


def test_host_packages_cover_every_fmu_import() -> None:
    from cosim.build.python import catalog
    from cosim.build.reference import third_party_imports

    listed = site.host_packages()
    for spec in catalog().values():
        for name in third_party_imports(spec.module):
            assert f"`{name}`" in listed
    assert "`cvxpy`" in listed and "`daqp`" in listed and "`skfuzzy`" in listed


def _site(tmp_path: Path) -> Path:
    pytest.importorskip("mkdocs")
    pytest.importorskip("material")
    pytest.importorskip("mkdocstrings_handlers.python")  # the API page (mkdocs.yml plugins)
    site = tmp_path / "site"
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
        cwd=ROOT, capture_output=True, text=True, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert result.returncode == 0, result.stderr[-3000:]
    return site


def test_site_builds_strict(tmp_path: Path) -> None:
    site = _site(tmp_path)
    for page in ("index.html", "cli/index.html", "fmus/index.html", "papers/index.html"):
        assert (site / page).is_file(), page


@pytest.mark.parametrize(("where", "language", "code"), _blocks(), ids=lambda v: str(v)[:40])
def test_bash_block_runs(where: str, language: str, code: str, tmp_path: Path) -> None:
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    cosim = bin_dir / "cosim"
    cosim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m cosim.cli "$@"\n')
    cosim.chmod(0o755)
    python = bin_dir / "python"  # a wrapper, not a symlink: a venv's interpreter finds its
    python.write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')  # packages by its own path
    python.chmod(0o755)
    work = tmp_path / "work"
    work.mkdir()
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}",
           "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    if "gcc" in code and shutil.which("gcc") is None:
        pytest.skip("gcc not installed")
    cmd = (["bash", "-euo", "pipefail", "-c", code] if language == "bash"
           else [sys.executable, "-c", code])
    result = subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True,
                            timeout=BLOCK_TIMEOUT_S)
    assert result.returncode == 0, (
        f"{where}:\n{code}\n{result.stdout[-2000:]}\n{result.stderr[-2000:]}")


def _chromium() -> str | None:
    return next((p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome"))
                 if p), None)


# Screenshots of every page of the site at 1280 px, kept after the browser tests (CI uploads
# the folder as an artefact): $ATO_COSIM_SCREENSHOTS, default runs/site-screenshots/.
SCREENSHOTS = Path(os.environ.get("ATO_COSIM_SCREENSHOTS", ROOT / "runs" / "site-screenshots"))
WIDTH_PX = 1280  # the reader's window
FIRST_SCREEN_PX = 800  # the height of a 1280 x 800 screen's window: what a reader sees unscrolled
MAX_SHOT_PX = 16000  # a full-page screenshot's height is the page's, up to this

# Run in each built page after it loads: what a reader sees, as JSON in a script element that
# --dump-dom prints (fence marks in the text, h2/h3 headings and whether the page's table of
# contents links them, images with their decoded size, where the claims tables' verdict and
# last columns sit against the window and their scrolling box, the page height).
_PROBE = """
window.addEventListener('load', () => setTimeout(() => {
  const art = document.querySelector('article');
  const toc = new Set([...document.querySelectorAll('nav.md-nav--secondary a.md-nav__link')]
    .map(a => decodeURIComponent((a.getAttribute('href') || '').split('#')[1] || '')));
  const out = {article: !!art, h1: !!(art && art.querySelector('h1')),
               nav: [...document.querySelectorAll('nav.md-nav--primary a.md-nav__link')]
                 .map(a => a.textContent.replace(/\\s+/g, ' ').trim()),
               height: document.documentElement.scrollHeight, width: window.innerWidth};
  if (art) {
    const text = art.innerText;
    // a paper page's citation (the paragraph under its title) and verdicts paragraph: their
    // bottoms; its headline paragraph: its top (page coordinates)
    const bottom = e => e ? e.getBoundingClientRect().bottom + window.scrollY : null;
    const top = e => e ? e.getBoundingClientRect().top + window.scrollY : null;
    const led = word => [...art.querySelectorAll('p')].find(
      p => (p.querySelector('strong') || {}).textContent === word);
    out.first_screen = {citation: bottom(art.querySelector('h1 + p')),
                        verdicts: bottom(led('Verdicts')), headline: top(led('Headline'))};
    out.fences = (text.match(/```/g) || []).length;
    out.headings = [...art.querySelectorAll('h2, h3')].map(h => (
      {id: h.id, text: h.textContent.replace('\u00b6', '').trim(), in_toc: toc.has(h.id)}));
    out.images = [...art.querySelectorAll('img')].map(i => (
      {src: i.getAttribute('src'), complete: i.complete, w: i.naturalWidth,
       h: i.naturalHeight}));
    out.claims_columns = [...art.querySelectorAll('th')]
      .filter(th => th.textContent.trim() === 'verdict').flatMap(th => {
        const box = (th.closest('.md-typeset__scrollwrap') || art).getBoundingClientRect();
        return [th, th.parentElement.lastElementChild].map(c => {
          const r = c.getBoundingClientRect();
          return {name: c.textContent.trim(), left: r.left, right: r.right,
                  box_left: box.left, box_right: box.right};
        });
      });
  }
  const s = document.createElement('script');
  s.type = 'application/json'; s.id = 'probe-result'; s.textContent = JSON.stringify(out);
  document.body.appendChild(s);
}, 0));
"""
_RESULT = re.compile(r'<script type="application/json" id="probe-result">(.*?)</script>', re.S)


def _browse(browser: str, profile: Path, url: str, *args: str) -> str:
    result = subprocess.run(
        [browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
         "--no-first-run", "--disable-background-networking", "--disable-component-update",
         "--disable-sync", f"--user-data-dir={profile}", "--allow-file-access-from-files",
         "--hide-scrollbars", "--virtual-time-budget=5000", *args, url],
        capture_output=True, text=True, timeout=180)
    assert result.returncode == 0, result.stderr[-2000:]
    return result.stdout


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict]:
    """Every page of the built site opened in headless Chromium at ``WIDTH_PX``: the probe's
    findings by page (``"papers/seed000/"``), and a full-page screenshot of each in
    ``SCREENSHOTS`` (``papers__seed000.png``; the home page ``index.png``)."""
    import json

    browser = _chromium()
    if browser is None:
        pytest.skip("no chromium on PATH (Debian: apt-get install chromium)")
    tmp = tmp_path_factory.mktemp("rendered")
    site = _site(tmp)
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    found: dict[str, dict] = {}
    names: set[str] = set()
    for page in sorted(site.rglob("index.html")):
        rel = page.parent.relative_to(site).as_posix()
        if rel.startswith("404"):
            continue
        page.write_text(page.read_text().replace("</body>", f"<script>{_PROBE}</script></body>"))
        dom = _browse(browser, tmp / "profile", page.as_uri(), f"--window-size={WIDTH_PX},900",
                      "--dump-dom")
        match = _RESULT.search(dom)
        assert match, (rel, dom[-2000:])
        probe = json.loads(match.group(1))
        name = "index" if rel == "." else rel.replace("/", "__")
        height = min(max(int(probe["height"]), 900), MAX_SHOT_PX)
        shot = tmp / f"{name}.png"
        _browse(browser, tmp / "profile", page.as_uri(), f"--window-size={WIDTH_PX},{height}",
                f"--screenshot={shot}")
        shots = {name: shot}
        if probe.get("first_screen", {}).get("verdicts"):  # a paper page: its first screen
            first = tmp / f"{name}__first_screen.png"
            _browse(browser, tmp / "profile", page.as_uri(),
                    f"--window-size={WIDTH_PX},{FIRST_SCREEN_PX}", f"--screenshot={first}")
            shots[first.stem] = first
        for stem, path in shots.items():
            # into the artefact folder whole (a copy, then an atomic rename): pytest-xdist may
            # run this fixture in two workers at once, and neither may see the other's
            # half-written or deleted file
            part = SCREENSHOTS / f".{stem}.{os.getpid()}.part"
            shutil.copyfile(path, part)
            os.replace(part, SCREENSHOTS / f"{stem}.png")
            names.add(stem)
        found["" if rel == "." else rel + "/"] = probe
    for old in SCREENSHOTS.glob("*.png"):  # pages the site no longer has
        if old.stem not in names:
            old.unlink()
    return found


@pytest.mark.slow
def test_every_page_renders_its_text_headings_and_figures(rendered: dict[str, dict]) -> None:
    """As a reader sees it: the article and its title, no fence marks shown as text (a fence
    the Markdown did not recognise), every h2/h3 heading linked from the
    page's table of contents, every image decoded with a non-zero size, a screenshot kept."""
    assert {"", "getting_started/", "architecture/", "cli/", "api/", "python/",
            "papers/"} <= set(rendered)
    api_headings = {h["text"].split()[0] for h in rendered["api/"]["headings"] if h["text"]}
    assert {"load", "run", "Run", "compare"} <= api_headings, api_headings  # from docstrings
    for page, probe in rendered.items():
        assert probe["article"] and probe["h1"], page
        assert probe["fences"] == 0, page
        missing = [h["text"] for h in probe["headings"] if not h["in_toc"]]
        assert not missing, (page, missing)
        bad = [i["src"] for i in probe["images"] if not (i["complete"] and i["w"] and i["h"])]
        assert not bad, (page, bad)
        name = "index" if not page else page.rstrip("/").replace("/", "__")
        assert (SCREENSHOTS / f"{name}.png").stat().st_size > 0, page
    first_run = next(h for h in rendered["getting_started/"]["headings"]
                     if h["text"] == "A first run")
    assert first_run["in_toc"]
    paper_images = [i for p, probe in rendered.items() if p.startswith("papers/")
                    for i in probe["images"]]
    assert paper_images or not list((DOCS / "papers").rglob("*.png"))


@pytest.mark.slow
def test_each_paper_shows_its_citation_and_verdicts_on_the_first_screen(
        rendered: dict[str, dict]) -> None:
    """On a 1280 x 800 screen, unscrolled, a paper's page shows its citation and its verdicts'
    counts whole and its headline reading begins (the first-screen screenshot of each kept
    beside its full page); the site's navigation names it by its title (author, year,
    topic)."""
    from cosim.reproduce.entry import load_entry

    papers = {p: probe for p, probe in rendered.items()
              if p.startswith("papers/") and p != "papers/"}
    assert len(papers) == len(list(DOCS.glob("papers/*.md"))) - 1, sorted(papers)  # index.md
    for page, probe in papers.items():
        entry = load_entry(page.split("/")[1])
        wanted = {"citation", "verdicts", *(["headline"] if any(
            s.headline for s in entry.statements) else [])}
        where = {k: v for k, v in probe["first_screen"].items() if k in wanted}
        assert all(where.values()) and max(where.values()) <= FIRST_SCREEN_PX, (page, where)
        name = page.rstrip("/").replace("/", "__")
        assert (SCREENSHOTS / f"{name}__first_screen.png").stat().st_size > 0, page
        # the navigation names the paper as its page's heading does, not by its file
        assert entry.title in probe["nav"], (page, entry.title, probe["nav"])


@pytest.mark.slow
def test_paper_claims_tables_fit_1280px(rendered: dict[str, dict]) -> None:
    """Each claims table's verdict column and its last column (rounding-robust) lie inside the
    window and inside the table's own scrolling box at 1280 px, so a reader sees the whole
    table without scrolling sideways."""
    from cosim.reproduce.verdicts import CLAIMS_HEADER

    papers = {p: probe for p, probe in rendered.items()
              if p.startswith("papers/") and p != "papers/"}
    columns = [(p, c) for p, probe in papers.items() for c in probe["claims_columns"]]
    assert columns, "no claims table with a verdict column on a paper page"
    assert {c["name"] for _, c in columns} == {"verdict", CLAIMS_HEADER[-1]}
    hidden = [(p, c["name"]) for p, c in columns
              if c["right"] > min(c["box_right"], WIDTH_PX) + 0.5 or c["left"] < c["box_left"]]
    assert not hidden, hidden


def test_a_modules_imports_are_read_again_when_it_changes(tmp_path: Path) -> None:
    """The FMU reference's imports of a bundled module, parsed once per content stamp: a
    changed file is parsed again; optional (in a try) and fallback (in a handler) imports."""
    import os

    from cosim.build.reference import _imports_of

    module = tmp_path / "m.py"
    module.write_text("import numpy\ntry:\n    import numba\nexcept ImportError:\n"
                      "    import tomli\nimport os\nfrom cosim import site\n")
    stat = module.stat()
    assert _imports_of(module, stat.st_mtime_ns, stat.st_size) == (
        frozenset({"numpy", "numba", "tomli"}), frozenset({"numba"}), frozenset({"tomli"}))
    module.write_text("import scipy\n")
    os.utime(module, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1))
    stat = module.stat()
    assert _imports_of(module, stat.st_mtime_ns, stat.st_size)[0] == frozenset({"scipy"})
