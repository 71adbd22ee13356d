"""Every public name of the three packages is documented, and listed in the API reference.

A name is public when it is in the ``__all__`` of ``fmscal.plant``, ``fmscal.observers`` or
``fmscal.analysis``, or of one of their subpackages (whose name does not start with an
underscore; every module is private). The API reference is written at each build from those
``__all__`` by ``docs/_api.py`` (autosummary lists, from which Sphinx generates a page per class
or function; constants documented on the package's page); CI builds the site with ``-W``; this
test checks what the pages list without building them.
"""

import importlib
import inspect
import sys
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs"))
import _api  # noqa: E402  (docs/_api.py)

PACKAGES = _api.PACKAGES


def public_names(package):
    """``{dotted path: object}`` of every public name of ``package`` and of its public subpackages."""
    pkg = importlib.import_module(package)
    names = {f"{package}.{n}": getattr(pkg, n) for n in pkg.__all__}
    for sub in _api.subpackages(package):
        module = importlib.import_module(sub)
        for n in module.__all__:
            names[f"{sub}.{n}"] = getattr(module, n)
    return names


def listed_names(text):
    """``{dotted path: kind}`` a page lists: ``"page"`` in autosummary blocks, ``"data"`` by ``py:data``."""
    listed, current, in_block = {}, None, False
    for line in text.splitlines():
        match = re.match(r"\.\. currentmodule:: (\S+)", line)
        data = re.match(r"\.\. py:data:: (\S+)", line)
        if match:
            current, in_block = match.group(1), False
        elif data:
            listed[f"{current}.{data.group(1)}"] = "data"
            in_block = False
        elif line.startswith(".. autosummary::"):
            in_block = True
        elif in_block and line.startswith("   ") and line.strip() and not line.strip().startswith(":"):
            listed[f"{current}.{line.strip()}"] = "page"
        elif in_block and line.strip() and not line.startswith(" "):
            in_block = False
    return listed


def resolve(path):
    module, _, name = path.rpartition(".")
    return getattr(importlib.import_module(module), name)


data_doc = _api.data_doc


def docstring(path, obj):
    if inspect.isclass(obj) or inspect.isroutine(obj):
        doc = (obj.__doc__ or "").strip()
        # dataclasses and named tuples make up a docstring, the signature: that is none.
        return "" if doc.startswith(f"{obj.__name__}(") else doc
    return data_doc(path)


ALL_PUBLIC = {path: obj for pkg in PACKAGES for path, obj in public_names(pkg).items()}
PAGES = {pkg: _api.page(pkg) for pkg in PACKAGES}


def test_the_packages_have_public_names():
    # Guards the collection itself: a broken walk must not pass every check vacuously.
    assert 100 < len(ALL_PUBLIC) < 600
    assert "fmscal.observers.AdaptiveObserver" in ALL_PUBLIC
    assert "fmscal.analysis.cli.main" in ALL_PUBLIC
    assert not any("._" in path for path in ALL_PUBLIC)


@pytest.mark.slow
@pytest.mark.parametrize("path", sorted(ALL_PUBLIC))
def test_public_name_has_a_docstring(path):
    assert docstring(path, ALL_PUBLIC[path]), f"{path} has no docstring (a '#:' comment for a constant)"


@pytest.mark.parametrize("package", PACKAGES)
def test_every_public_name_is_in_the_api_reference(package):
    listed = listed_names(PAGES[package])
    missing = []
    for path, obj in public_names(package).items():
        name = path.rpartition(".")[2]
        # Listed under this path, or under another public path to the same object and name
        # (a class defined in a subpackage and exported by its package is listed once).
        if path not in listed and not any(
                other.rpartition(".")[2] == name and other in ALL_PUBLIC and ALL_PUBLIC[other] is obj
                for other in listed):
            missing.append(path)
    assert not missing, f"public names missing from the {package} page: {missing}"


@pytest.mark.parametrize("package", PACKAGES)
def test_the_api_reference_lists_only_public_names_and_constants_get_no_page(package):
    listed = listed_names(PAGES[package])
    assert len(listed) > 15
    stale = [path for path in listed if path not in ALL_PUBLIC]
    assert not stale, f"the {package} page lists names that are not public: {stale}"
    paged_data = [path for path, kind in listed.items() if kind == "page" and _api.is_data(ALL_PUBLIC[path])]
    assert not paged_data, f"constants with a page of their own (in the sidebar): {paged_data}"
    assert any(kind == "data" for kind in listed.values()) or package == "fmscal.analysis"


@pytest.mark.slow
def test_the_pages_are_written_from_the_packages(tmp_path):
    # What Sphinx reads is what this test checks: docs/conf.py writes these very pages.
    paths = _api.write_pages(tmp_path)
    assert [p.read_text() for p in paths] == [PAGES[pkg] for pkg in PACKAGES]
    assert "write_pages(HERE / \"api\")" in (ROOT / "docs" / "conf.py").read_text()


def summary_cuts(doc):
    """Where autosummary would end ``doc``'s first sentence too early: each period followed by a space and a lower-case
    letter, a digit or a parenthesis (no sentence starts so) whose text up to it does not end with one of
    :data:`_api.SUMMARY_ABBREVIATIONS`; as ``[text up to it]``."""
    stanza = " ".join(inspect.cleandoc(doc or "").split("\n\n")[0].split())
    return [stanza[:m.end(1) + 1] for m in re.finditer(r"(\S+)\.\s+(?=[a-z(0-9])", stanza)
            if not stanza[:m.end(1) + 1].endswith(_api.SUMMARY_ABBREVIATIONS)]


def test_no_summary_is_cut_at_an_abbreviation():
    # The rule, both ways: cut at "eq." without the list, whole with it; autosummary is given the list.
    assert summary_cuts("E of eq. (16) on a 6x6 S. More.") == []
    assert summary_cuts("E of ref. (16) on a 6x6 S.") == ["E of ref."]
    assert "SUMMARY_ABBREVIATIONS" in (ROOT / "docs" / "conf.py").read_text()
    cut = {path: summary_cuts(obj.__doc__) for path, obj in ALL_PUBLIC.items() if not _api.is_data(obj)}
    cut = {path: where for path, where in cut.items() if where}
    assert not cut, f"summaries autosummary would cut at an abbreviation (add it to SUMMARY_ABBREVIATIONS): {cut}"


#: Folders the documentation's build writes (git-ignored): a link into them is broken where the pages are read as
#: Markdown (on GitHub).
BUILT = ("docs/_build", "docs/tutorials/notebooks", "docs/api/generated", "docs/api/plant.rst",
         "docs/api/observers.rst", "docs/api/analysis.rst")


def broken_links(page, text=None):
    """The relative links of a Markdown ``page`` (code blocks, web addresses and anchors left out) that name no file
    of the repository: missing, or in a folder the build writes. ``text``: the page's, if not its file's."""
    built = [(ROOT / b).resolve() for b in BUILT]
    text = re.sub(r"^```.*?^```", "", page.read_text() if text is None else text, flags=re.S | re.M)
    links = [m.group(1) for m in re.finditer(r"\]\(([^)\s]+)\)", text)
             if not re.match(r"[a-z]+:", m.group(1)) and not m.group(1).startswith("#")]
    targets = [(link, (page.parent / link.split("#")[0]).resolve()) for link in links]
    return [link for link, t in targets if not t.exists() or any(b == t or b in t.parents for b in built)]


def test_every_relative_link_reads_as_markdown():
    # On GitHub a link must name a file of the repository; docs/conf.py turns the links to notebooks/ into links
    # to their executed copies for the site. The check itself first: a link into the build's copy is broken.
    probe = "[a](../tutorials/notebooks/08_on_a_robot.ipynb) [b](../../notebooks/08_on_a_robot.ipynb) [c](nowhere.md)"
    assert broken_links(ROOT / "docs" / "guide" / "probe.md", probe) == ["../tutorials/notebooks/08_on_a_robot.ipynb",
                                                                         "nowhere.md"]
    built = [(ROOT / b).resolve() for b in BUILT]
    pages = [ROOT / "README.md", ROOT / "examples" / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    pages = [p for p in pages if not any(b in p.parents for b in built)]
    broken = {str(page.relative_to(ROOT)): broken_links(page) for page in pages}
    assert len(pages) > 20 and not any(broken.values()), {k: v for k, v in broken.items() if v}
    assert "_notebook_links" in (ROOT / "docs" / "conf.py").read_text()


def test_the_readme_rounds_the_test_suites_times_docs_speed_gives():
    # docs/speed.md holds the measured figures (its command beside them); README rounds them to half minutes.
    section = (ROOT / "docs" / "speed.md").read_text().split("## The test suite")[1]
    fast = re.search(r'-m "not slow"`.*?(\d+) tests in (\d+) s', section, flags=re.S)
    slow = re.search(r"-m slow`: (\d+) tests in (\d+) s", section)
    readme = (ROOT / "README.md").read_text()

    def minutes(seconds):
        return f"{round(int(seconds) / 30) / 2:g} min"

    assert fast and slow and int(fast.group(1)) > int(slow.group(1)) > 10
    assert f"(about {minutes(fast.group(2))} on 2 cores)" in readme
    assert f"(about {minutes(slow.group(2))} more on 2 cores)" in readme


#: The widest line a code block on the documentation's front page may have: its column, at the theme's font.
FRONT_PAGE_WIDTH = 80


def test_the_front_pages_code_fits_its_column():
    text = (ROOT / "docs" / "index.md").read_text()
    code = re.findall(r"^```\w*\n(.*?)^```", text, flags=re.S | re.M)
    lines = [line for block in code for line in block.splitlines()]
    assert lines and max(map(len, lines)) <= FRONT_PAGE_WIDTH, max(lines, key=len)


def test_the_front_page_names_compensation_and_the_node():
    text = (ROOT / "docs" / "index.md").read_text()
    assert "guide/compensation.md" in text and "guide/robot.md" in text and "fmscal ros2" in text


def test_data_docs_are_found_and_missing_ones_are_not():
    # The '#:' reader itself, both ways: a documented constant, a package re-export, a non-name.
    assert "Times" in data_doc("fmscal.analysis._comparison.CHECKPOINTS")
    assert data_doc("fmscal.plant.PAPER_S")
    assert data_doc("fmscal.analysis._comparison.no_such_constant") == ""
