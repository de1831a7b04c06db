"""The documentation site: generated pages current, the site builds with warnings as errors,
every runnable block of the docs runs, and (slow) the built pages render in a headless Chromium
as a reader sees them.

Convention for code blocks in ``docs/*.md``: a ```` ```bash ```` block is run by
:func:`test_bash_block_runs` in a fresh temporary folder, with this checkout's ``cosim`` first
on ``PATH``, and must exit 0 within ``BLOCK_TIMEOUT_S``; ```` ```python ```` blocks are executed
as scripts the same way. An HTML comment ``<!-- norun -->`` on the line right before the fence
marks a block shown only (installs, long runs): the comment is invisible in the rendered page,
and the fence's info string stays one word, which is all the site's Markdown (Python-Markdown
with pymdownx.superfences) recognises; ```` ```bash norun ```` is not a fence there and swallows
the text after it into a code box. Other fences (toml, text, sh, c) are data or other languages.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cosim.cli import app, cli_reference
from cosim.run import docs_pages

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
BLOCK_TIMEOUT_S = 600  # a block builds the FMUs it runs: minutes on a loaded 2-core machine
NORUN = "<!-- norun -->"  # on the line before a fence: the block is shown, not run
_FENCE = re.compile(r"^(<!-- norun -->\n)?```(bash|python)[ \t]*\n(.*?)^```[ \t]*$",
                    re.M | re.S)
_OPENING = re.compile(r"^[ \t]*```(.*)$", re.M)  # every fence line: opening or closing


def _blocks() -> list[tuple[str, str, str]]:
    found = []
    for page in sorted(DOCS.rglob("*.md")):
        for i, m in enumerate(_FENCE.finditer(page.read_text())):
            if not m.group(1):
                found.append((f"{page.relative_to(DOCS)}#{i}", m.group(2), m.group(3)))
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
    run = [code for _, _, code in _blocks()]
    assert run and not any("pip install" in code for code in run)  # installs are shown only


def test_generated_pages_are_current() -> None:
    result = CliRunner().invoke(app, ["docs", "--check"])
    assert result.exit_code == 0, result.output


def test_check_names_a_stale_page(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text("old\n")
    assert docs_pages.stale(iter([(page, b"new\n")])) == [page]
    assert docs_pages.stale(iter([(page, b"old\n")])) == []
    assert docs_pages.stale(iter([(tmp_path / "missing.md", b"x")])) == [tmp_path / "missing.md"]


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
    (run / "claims.md").write_text("## Claims\n\n![a](fig/a.png) [web](https://x.org/y.png)\n")
    (run / "fig" / "a.png").write_bytes(b"PNG")
    page = docs_pages.paper_page("seedX", run)
    assert page is not None
    text = page[DOCS / "papers" / "seedX.md"].decode()
    assert text.count("# Claims") == 1
    assert "![a](seedX/fig/a.png)" in text and "(https://x.org/y.png)" in text
    assert page[DOCS / "papers" / "seedX" / "fig" / "a.png"] == b"PNG"
    (run / "table.md").write_text("## T\n\nthe table, claims, figures and notes\n")
    page = docs_pages.paper_page("seedX", run)
    assert b"the table, claims" in page[DOCS / "papers" / "seedX.md"]
    assert docs_pages.paper_page("seedY", tmp_path / "none") is None


def test_fill_generated_replaces_only_its_block() -> None:
    text = "a <!-- generated: k -->old<!-- end generated --> b"
    assert docs_pages.fill_generated(text, "k", "new") == (
        "a <!-- generated: k -->new<!-- end generated --> b")
    with pytest.raises(ValueError, match="generated: other"):
        docs_pages.fill_generated(text, "other", "x")


def test_host_packages_cover_every_fmu_import() -> None:
    from cosim.fmu.build import catalog
    from cosim.fmu.reference import third_party_imports

    listed = docs_pages.host_packages()
    for spec in catalog().values():
        for name in third_party_imports(spec.module):
            assert f"`{name}`" in listed
    assert "`cvxpy`" in listed and "`daqp`" in listed and "`skfuzzy`" in listed


def _site(tmp_path: Path) -> Path:
    pytest.importorskip("mkdocs")
    pytest.importorskip("material")
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


@pytest.mark.slow
def test_site_renders_in_chromium(tmp_path: Path) -> None:
    """Each page's main text and every figure it shows load in a headless browser: a probe
    page loads the site's images and writes their decoded sizes into the DOM Chromium dumps."""
    browser = _chromium()
    if browser is None:
        pytest.skip("no chromium on PATH (Debian: apt-get install chromium)")
    site = _site(tmp_path)

    def dump(url: str) -> str:
        result = subprocess.run(
            [browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
             "--no-first-run", "--disable-background-networking", "--disable-component-update",
             "--disable-sync", f"--user-data-dir={tmp_path / 'profile'}",
             "--allow-file-access-from-files", "--virtual-time-budget=5000", "--dump-dom", url],
            capture_output=True, text=True, timeout=120)
        assert result.returncode == 0, result.stderr[-2000:]
        return result.stdout

    pages = sorted(site.rglob("index.html"))
    images = []
    for page in pages:
        if "404" in page.parts:
            continue
        dom = dump(page.as_uri())
        assert "<article" in dom and "<h1" in dom, page
        srcs = re.findall(r'<img[^>]+src="([^"]+)"', dom)
        images += [(page.parent / src).resolve() for src in srcs
                   if not src.startswith(("http", "data:"))]
    assert any("papers" in str(i) for i in images) or not list((DOCS / "papers").rglob("*.png"))
    probe = site / "probe.html"
    probe.write_text(
        "<html><body><div id=out></div><script>const srcs=" + repr([i.as_uri() for i in images])
        + ";for(const s of srcs){const im=new Image();im.onload=()=>{"
        "document.getElementById('out').insertAdjacentHTML('beforeend',"
        "'<p class=ok>'+im.naturalWidth+'</p>');};"
        "im.onerror=()=>{document.getElementById('out').insertAdjacentHTML('beforeend',"
        "'<p class=bad>'+s+'</p>');};im.src=s;}</script></body></html>")
    dom = dump(probe.as_uri())
    assert 'class="bad"' not in dom, dom[-2000:]
    widths = [int(w) for w in re.findall(r'<p class="ok">(\d+)</p>', dom)]
    assert len(widths) == len(images) and all(w > 100 for w in widths), (widths, len(images))
