"""Every command in the spatial and wrist guides runs as written, from a copy of the repository's example data.

The ``bash`` code blocks of the guides in :data:`GUIDES` are split into commands (a line ending in
``\\`` joined to the next, ``#`` comments dropped) and each is run word for word, in order, in a
temporary folder holding a copy of ``examples/`` (so that ``examples/arm.csv`` resolves as it does
at the top of a clone, and every file a command writes stays there): ``fmscal WORDS`` as
``fmscal.analysis.cli.main(WORDS)`` in this process (the entry point's own function; a new
interpreter per command would cost seconds of imports each). A command succeeds with exit status 0;
one whose comment in the guide says ``exit status 2`` (a refusal the guide shows) must give that.
The guides' ``python`` blocks run after the page's commands, in the same folder, each in a fresh
namespace. Of the pages in :data:`PAGES` (the README, the documentation's front page) only the
commands and python blocks that read ``examples/`` run.

Only exit statuses, files and keys are asserted, never printed figures: other changes move those.
The runs take tens of seconds, so they are marked ``slow``; the fast tests check the extraction
and that every example file the commands name exists.
"""

import contextlib
import io
import re
import shlex
import shutil
from pathlib import Path

import pytest

from fmscal.analysis.cli import main

ROOT = Path(__file__).resolve().parents[1]
#: The guides whose commands run verbatim on the example data, every one.
GUIDES = ("docs/guide/spatial.md", "docs/guide/wrist-sensor.md")
#: Pages of which the commands and python blocks that read the example data run (their others need a rig or
#: an install: ``pip install``, ``LOG.csv``).
PAGES = ("README.md", "docs/index.md")


def blocks(text, language):
    """The code blocks of ``language`` in a markdown ``text``, each as its text."""
    return re.findall(r"^```" + language + r"[ \t]*\n(.*?)^```", text, flags=re.S | re.M)


def commands(block):
    """``[(words, expected exit status)]`` of a bash block: continued lines joined, comments dropped."""
    out = []
    for line in block.replace("\\\n", " ").splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        words = shlex.split(line, comments=True)
        status = 2 if re.search(r"#.*exit status 2", line) else 0
        out.append((words, status))
    return out


def guide_commands(guide):
    return [c for block in blocks((ROOT / guide).read_text(), "bash") for c in commands(block)]


def run_fmscal(words):
    """``fmscal WORDS`` in this process: ``(status, stdout, stderr)``."""
    assert words[0] == "fmscal", f"not an fmscal command: {shlex.join(words)}"
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main(words[1:])
    return status, out.getvalue(), err.getvalue()


@pytest.fixture
def clone(tmp_path, monkeypatch):
    """A folder holding a copy of ``examples/`` (no ``make.py`` output beyond the checked-in files), the cwd."""
    shutil.copytree(ROOT / "examples", tmp_path / "examples", ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_the_commands_are_found_and_joined():
    block = "fmscal calibrate a.csv --mass 1 \\\n    --com 0 0 1   # the payload\n# a note\nfmscal x  # exit status 2\n"
    assert commands(block) == [(["fmscal", "calibrate", "a.csv", "--mass", "1", "--com", "0", "0", "1"], 0),
                               (["fmscal", "x"], 2)]
    for guide in GUIDES:
        found = guide_commands(guide)
        assert len(found) >= 5 and all(words[0] == "fmscal" for words, _ in found), guide


@pytest.mark.parametrize("guide", GUIDES + PAGES)
def test_every_example_file_the_commands_read_exists(guide):
    named = {w for words, _ in guide_commands(guide) for w in words if w.startswith("examples/")}
    text = (ROOT / guide).read_text()
    named |= set(re.findall(r"[\"'](examples/[^\"']+)[\"']", "\n".join(blocks(text, "python"))))
    assert named, guide
    missing = sorted(n for n in named if not (ROOT / n).exists())
    assert not missing, f"{guide} reads example files that are not in examples/: {missing}"


def test_a_failing_command_fails_the_runner(clone):
    # The runner itself, both ways: a command the guide expects to succeed that refuses is a failure.
    status, _, err = run_fmscal(["fmscal", "identify-payload", "examples/no-such.csv"])
    assert status == 2 and "no such file" in err


def _run_guide(guide):
    text = (ROOT / guide).read_text()
    for words, expected in guide_commands(guide):
        status, out, err = run_fmscal(words)
        assert status == expected, f"{shlex.join(words)}: exit status {status}, expected {expected}\n{err[-2000:]}"
    for code in blocks(text, "python"):
        exec(compile(code, f"{guide} (python block)", "exec"), {"__name__": "__guide__"})


@pytest.mark.slow
def test_the_spatial_guide_runs_as_written(clone):
    _run_guide("docs/guide/spatial.md")
    for name in ("cal.json", "wrench.csv", "run.csv"):
        assert (clone / name).stat().st_size > 0, name


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
def test_what_a_page_runs_on_the_example_data_runs_as_written(clone, page):
    text = (ROOT / page).read_text()
    ran = 0
    for words, expected in guide_commands(page):
        if any(w.startswith("examples/") for w in words):
            status, _, err = run_fmscal(words)
            assert status == expected, f"{shlex.join(words)}: exit status {status}\n{err[-2000:]}"
            ran += 1
    for code in blocks(text, "python"):
        if "examples/" in code:
            exec(compile(code, f"{page} (python block)", "exec"), {"__name__": "__guide__"})
            ran += 1
    assert ran


@pytest.mark.slow
def test_the_wrist_guide_runs_as_written(clone):
    _run_guide("docs/guide/wrist-sensor.md")
    for name in ("arm.csv", "payload.json", "cal.json", "wrench.csv"):
        assert (clone / name).stat().st_size > 0, name


def test_every_example_file_any_page_names_exists():
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    pages = [p for p in pages if "_build" not in p.parts]
    named = {(p.relative_to(ROOT).as_posix(), m.rstrip(".,;:)")) for p in pages
             for m in re.findall(r"(?<![\w/.])examples/[\w./-]*", p.read_text())}
    assert any(page == "docs/guide/spatial.md" for page, _ in named)
    missing = sorted((page, n) for page, n in named if not (ROOT / n).exists())
    assert not missing, f"pages name example files that are not in examples/: {missing}"
