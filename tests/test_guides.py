"""Every command of the user guides runs as written, from a copy of the repository's example data, and the guides
run in turn, in one folder, in the order the guide's index lists them.

The ``bash`` code blocks of the guides in :data:`GUIDES` are split into commands (a line ending in ``\\`` joined to
the next, ``#`` comments dropped) and each is run word for word, in order, in a folder holding a copy of
``examples/`` (so that ``examples/arm.csv`` resolves as it does at the top of a clone, and every file a command
writes stays there): ``fmscal WORDS`` as ``fmscal.analysis.cli.main(WORDS)`` in this process (the entry point's
own function; a new interpreter per command would cost seconds of imports each), ``python -c CODE`` as ``CODE``
executed here. A command succeeds with exit status 0; one whose comment in the guide says ``exit status 2`` (a
refusal the guide shows) must give that. The guides' ``python`` blocks run after the page's commands, in the same
folder, each in a fresh namespace.

A user reads the guides in the index's order (``docs/guide/index.md``) in one folder: the files one guide writes
are there when the next runs, so the guides give distinct names to what they write, or ``--overwrite`` where a
user would make the same file again. The slow tests run them so, each guide after the ones before it; the
compensation guide also runs alone, as a user who opens only it would run it. Of the pages in :data:`PAGES` (the
README, the documentation's front page) only the commands and python blocks that read ``examples/`` run.

Only exit statuses, files and keys are asserted, never printed figures: other changes move those. The runs take
minutes, so they are marked ``slow``; the fast tests check the extraction, the order, and that every example
file the commands name exists.
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
#: The guide pages whose commands do not run here, and why (each is in the index; every other page runs).
NOT_RUN = {"robot": "its commands start the ROS 2 node and call its services on a running ROS 2 graph "
                    "(tests/test_ros2.py runs the node)"}


def guide_order():
    """The guide pages in the order of the index's toctree (``docs/guide/index.md``), as ``docs/guide/NAME.md``."""
    text = (ROOT / "docs" / "guide" / "index.md").read_text()
    toctree = re.search(r"^```\{toctree\}\n(.*?)^```", text, flags=re.S | re.M).group(1)
    names = [line.strip() for line in toctree.splitlines() if line.strip() and not line.startswith(":")]
    return [f"docs/guide/{name}.md" for name in names]


#: The guides whose commands run verbatim on the example data, every one, in the index's order.
GUIDES = tuple(g for g in guide_order() if Path(g).stem not in NOT_RUN)
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


def run_command(words):
    """``fmscal WORDS`` or ``python -c CODE`` in this process: ``(status, stdout, stderr)``."""
    out, err = io.StringIO(), io.StringIO()
    if words[:2] == ["python", "-c"] and len(words) == 3:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            exec(compile(words[2], "python -c", "exec"), {"__name__": "__main__"})
        return 0, out.getvalue(), err.getvalue()
    assert words[0] == "fmscal", f"not an fmscal or python -c command: {shlex.join(words)}"
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main(words[1:])
    return status, out.getvalue(), err.getvalue()


def copy_examples(folder):
    """``folder`` with a copy of ``examples/`` in it, as the top of a clone has it."""
    shutil.copytree(ROOT / "examples", folder / "examples", ignore=shutil.ignore_patterns("__pycache__"))
    return folder


@pytest.fixture
def clone(tmp_path, monkeypatch):
    """A folder holding a copy of ``examples/`` (no ``make.py`` output beyond the checked-in files), the cwd."""
    monkeypatch.chdir(copy_examples(tmp_path))
    return tmp_path


def test_the_commands_are_found_and_joined():
    block = "fmscal calibrate a.csv --mass 1 \\\n    --com 0 0 1   # the payload\n# a note\nfmscal x  # exit status 2\n"
    assert commands(block) == [(["fmscal", "calibrate", "a.csv", "--mass", "1", "--com", "0", "0", "1"], 0),
                               (["fmscal", "x"], 2)]
    for guide in ("docs/guide/spatial.md", "docs/guide/wrist-sensor.md", "docs/guide/compensation.md"):
        found = guide_commands(guide)
        assert len(found) >= 5 and all(words[0] == "fmscal" for words, _ in found), guide
    for guide in GUIDES:
        assert all(words[0] == "fmscal" or words[:2] == ["python", "-c"] for words, _ in guide_commands(guide)), guide


def test_the_guides_run_in_the_order_of_the_index():
    order = guide_order()
    assert len(order) >= 10 and all((ROOT / g).exists() for g in order)
    assert set(NOT_RUN) <= {Path(g).stem for g in order}
    assert list(GUIDES) == [g for g in order if Path(g).stem not in NOT_RUN]
    assert GUIDES.index("docs/guide/calibrating.md") < GUIDES.index("docs/guide/spatial.md") < \
        GUIDES.index("docs/guide/wrist-sensor.md") < GUIDES.index("docs/guide/compensation.md")


def example_files(guide):
    """The ``examples/`` files a page's commands and python blocks read."""
    named = {w for words, _ in guide_commands(guide) for w in words if w.startswith("examples/")}
    text = (ROOT / guide).read_text()
    return named | set(re.findall(r"[\"'](examples/[^\"']+)[\"']", "\n".join(blocks(text, "python"))))


@pytest.mark.parametrize("guide", GUIDES + PAGES)
def test_every_example_file_the_commands_read_exists(guide):
    missing = sorted(n for n in example_files(guide) if not (ROOT / n).exists())
    assert not missing, f"{guide} reads example files that are not in examples/: {missing}"


def test_the_pages_that_use_example_data_name_it():
    for guide in ("docs/guide/spatial.md", "docs/guide/wrist-sensor.md", "docs/guide/compensation.md", *PAGES):
        assert example_files(guide), guide
    assert {"examples/joint_log.csv", "examples/imu_log.csv"} <= example_files("docs/guide/compensation.md")


def test_a_failing_command_fails_the_runner(clone):
    # The runner itself, both ways: a command the guide expects to succeed that refuses is a failure.
    status, _, err = run_command(["fmscal", "identify-payload", "examples/no-such.csv"])
    assert status == 2 and "no such file" in err
    assert run_command(["python", "-c", "print(1 + 1)"])[:2] == (0, "2\n")
    with pytest.raises(ZeroDivisionError):
        run_command(["python", "-c", "1 / 0"])


def _run_guide(guide):
    text = (ROOT / guide).read_text()
    for words, expected in guide_commands(guide):
        status, out, err = run_command(words)
        assert status == expected, f"{shlex.join(words)}: exit status {status}, expected {expected}\n{err[-2000:]}"
    for code in blocks(text, "python"):
        exec(compile(code, f"{guide} (python block)", "exec"), {"__name__": "__guide__"})


#: What each guide leaves in the folder (a few of its files, checked after it runs).
WRITES = {"docs/guide/calibrating.md": ("rig.csv", "cal.json", "wrench.csv", "arm_cal.json"),
          "docs/guide/ros-bags.md": ("real_rig.csv", "imported.csv", "imported.import.json"),
          "docs/guide/log-format.md": ("logs/paper.csv", "logs/tv.csv", "logs/50hz.csv", "logs/rig.csv"),
          "docs/guide/spatial.md": ("arm_cal.json", "arm_wrench.csv", "run.csv", "sim.csv", "held.csv"),
          "docs/guide/wrist-sensor.md": ("wrist.csv", "payload.json", "wrist_cal.json", "wrist_wrench.csv"),
          "docs/guide/compensation.md": ("arm_cal.json", "contact.csv", "causal.csv", "tool.json", "new_tool.csv",
                                         "joints_contact.csv", "imu_contact.csv", "base_contact.csv",
                                         "tracked_fit.csv")}


def test_what_the_guides_write_is_named_in_them():
    assert set(WRITES) <= set(GUIDES)
    for guide, names in WRITES.items():
        text = (ROOT / guide).read_text()
        assert all(name in text for name in names), guide


@pytest.fixture(scope="module")
def reader(tmp_path_factory):
    """One folder for the guides run in turn, and which of them ran: ``{"folder", "ran": {guide: error or None}}``."""
    return {"folder": copy_examples(tmp_path_factory.mktemp("reader")), "ran": {}}


@pytest.mark.slow
@pytest.mark.parametrize("guide", GUIDES)
def test_the_guides_run_in_turn_in_one_folder(guide, reader, monkeypatch):
    # Each guide after every guide before it in the index, in the same folder (any not run yet runs first).
    monkeypatch.chdir(reader["folder"])
    for earlier in GUIDES[:GUIDES.index(guide) + 1]:
        if earlier not in reader["ran"]:
            try:
                _run_guide(earlier)
                reader["ran"][earlier] = None
            except Exception as err:
                reader["ran"][earlier] = err
                raise
        if reader["ran"][earlier] is not None:
            pytest.fail(f"{earlier}, run before {guide}, failed: {reader['ran'][earlier]}"[:3000])
    for name in WRITES.get(guide, ()):
        assert (reader["folder"] / name).stat().st_size > 0, f"{guide}: {name}"


@pytest.mark.slow
def test_the_compensation_guide_runs_alone(clone):
    # A user who opens this page alone: it makes its own calibration, its commands read only examples/.
    _run_guide("docs/guide/compensation.md")
    for name in WRITES["docs/guide/compensation.md"]:
        assert (clone / name).stat().st_size > 0, name


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
def test_what_a_page_runs_on_the_example_data_runs_as_written(clone, page):
    text = (ROOT / page).read_text()
    ran = 0
    for words, expected in guide_commands(page):
        if any(w.startswith("examples/") for w in words):
            status, _, err = run_command(words)
            assert status == expected, f"{shlex.join(words)}: exit status {status}\n{err[-2000:]}"
            ran += 1
    for code in blocks(text, "python"):
        if "examples/" in code:
            exec(compile(code, f"{page} (python block)", "exec"), {"__name__": "__guide__"})
            ran += 1
    assert ran


def test_every_example_file_any_page_names_exists():
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    pages = [p for p in pages if "_build" not in p.parts]
    named = {(p.relative_to(ROOT).as_posix(), m.rstrip(".,;:)")) for p in pages
             for m in re.findall(r"(?<![\w/.])examples/[\w./-]*", p.read_text())}
    assert any(page == "docs/guide/spatial.md" for page, _ in named)
    missing = sorted((page, n) for page, n in named if not (ROOT / n).exists())
    assert not missing, f"pages name example files that are not in examples/: {missing}"
