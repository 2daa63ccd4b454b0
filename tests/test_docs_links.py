"""README.md and docs/*.md: every relative link (and image) points at an existing file, and a #fragment into a
markdown page at one of its headings; the README is a front door of at most 250 lines, with exactly the two set-up
commands, that speaks of the software only (no work-log words: sessions, issue numbers, commit hashes)."""

import re
import subprocess
from pathlib import Path
from urllib.parse import unquote

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").glob("*.md"))]
SETUP = ["bash scripts/setup.sh && .venv/bin/manifoldgen demo     # the main job",
         "bash scripts/setup.sh && .venv/bin/python -m pytest --full -n 2     # the tests (what .ci/run calls)"]

FENCE = re.compile(r"^[ \t]*(```|~~~)[^\n]*\n.*?^[ \t]*\1[ \t]*$", re.S | re.M)
CODE_SPAN = re.compile(r"(`+)(.+?)\1", re.S)
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*<?([^)\s>]*)>?(?:\s+\"[^\"]*\")?\s*\)")
REFERENCE = re.compile(r"^[ \t]{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s|$)", re.M)
SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")
HEADING = re.compile(r"^#{1,6}[ \t]+(.+?)[ \t#]*$", re.M)

# work-log words that a README about the software does not use
SESSION = re.compile(r"\bsessions?\b", re.I)
ISSUE = re.compile(r"\bissues?\s*(?:#\s*\d+|\d+\b)|\bissue\s*#", re.I)
HEX = re.compile(r"(?<![0-9A-Za-z_.-])[0-9a-f]{7,40}(?![0-9A-Za-z_-])")
COMMIT = re.compile(r"\bcommits?\s+`?[0-9a-f]{7,40}\b", re.I)


def prose(text: str) -> str:
    """The text without fenced code blocks and code spans: what a renderer turns into links and headings."""
    return CODE_SPAN.sub("", FENCE.sub("", text))


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: link markup to its text, lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading).replace("`", "")
    return re.sub(r"[^\w\- ]", "", text.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    found: set[str] = set()
    for heading in HEADING.findall(FENCE.sub("", page.read_text(encoding="utf-8"))):
        base = slug(heading)
        name, n = base, 0
        while name in found:  # a repeated heading gets -1, -2, ...
            n += 1
            name = f"{base}-{n}"
        found.add(name)
    return found


def links(page: Path) -> list[str]:
    text = prose(page.read_text(encoding="utf-8"))
    return LINK.findall(text) + REFERENCE.findall(text)


def commit_like(word: str) -> bool:
    """7 to 40 lower-case hex characters with both a digit and a letter: a (short) commit hash, not a number or word."""
    return bool(re.search(r"\d", word)) and bool(re.search(r"[a-f]", word))


def test_the_checks_tell_links_and_work_log_words_apart():
    assert slug("Scoreboard: the learned sampler against C++ OMPL Atlas") == \
        "scoreboard-the-learned-sampler-against-c-ompl-atlas"
    assert slug("OMPL's sphere demo") == "ompls-sphere-demo"
    assert slug("Set up and run (fresh machine, Python 3.11)") == "set-up-and-run-fresh-machine-python-311"
    assert LINK.findall("see [the page](docs/a.md#b) and ![pic](img/x.png \"t\")") == ["docs/a.md#b", "img/x.png"]
    assert LINK.findall(prose("`[not](a link)` and\n```\n[nor](this)\n```\n")) == []
    assert SESSION.search("as measured this session") and not SESSION.search("possession, obsessions")
    assert ISSUE.search("issue 12") and ISSUE.search("Issue #9") and ISSUE.search("issues 3")
    assert not ISSUE.search("a known issue with OMPL") and not ISSUE.search("issues are welcome")
    words = [w for span in CODE_SPAN.findall("`git show 5cb5b63`, `deadbeef`, `1234567`, `0.00761`, `a0e3928x`, "
                                             "`sha256`, `decade1`") for w in HEX.findall(span[1])]
    assert [w for w in words if commit_like(w)] == ["5cb5b63", "decade1"]
    assert COMMIT.search("at commit 3049c7c") and not COMMIT.search("commit the dataset")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_relative_link_points_at_an_existing_file(page):
    for target in links(page):
        if not target or SCHEME.match(target):  # http(s):, mailto: ...
            continue
        path, _, fragment = unquote(target).partition("#")
        file = (page.parent / path).resolve() if path else page
        assert file.exists(), f"{page.name}: link to {target}: no such file"
        if fragment and file.suffix == ".md":
            assert fragment in anchors(file), f"{page.name}: link to {target}: no such heading in {file.name}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_the_pages_speak_of_the_software_not_of_the_work_log(page):
    text = page.read_text(encoding="utf-8")
    assert not SESSION.findall(text), f"{page.name}: 'session'"
    assert not ISSUE.findall(text), f"{page.name}: issue numbers {ISSUE.findall(text)}"
    assert not COMMIT.findall(text), f"{page.name}: commit hashes {COMMIT.findall(text)}"
    code = [span for _, span in CODE_SPAN.findall(FENCE.sub("", text))] + [m.group(0) for m in FENCE.finditer(text)]
    in_code = [w for span in code for w in HEX.findall(span) if commit_like(w)]
    assert not in_code, f"{page.name}: commit-like words in backticks: {in_code}"


def test_the_readme_is_a_short_front_door():
    text = README.read_text(encoding="utf-8")
    lines = text.splitlines()
    assert len(lines) <= 250, f"README.md has {len(lines)} lines"
    assert "../shared" not in text
    setup = [line for line in lines if "scripts/setup.sh &&" in line]
    assert setup == SETUP, "the two set-up commands, exactly, and no others"
    assert "pip install" not in text
    assert "docs/benchmarks.md" in text and "docs/python-api.md" in text and "docs/tasks.md" in text


def test_the_code_speaks_of_the_software_not_of_the_work_log():
    """No issue numbers in the code, the tests, the scripts, the task files or the benchmarks either."""
    tracked = subprocess.run(["git", "ls-files", "*.py", "*.sh", "*.toml", "*.cpp", "*.hpp", "*.json"], cwd=ROOT,
                             capture_output=True, text=True).stdout.split()
    if not tracked:
        pytest.skip("not a git checkout")
    found = {name: ISSUE.findall((ROOT / name).read_text(encoding="utf-8", errors="replace")) for name in tracked
             if name != "tests/test_docs_links.py" and (ROOT / name).is_file()}
    assert not {k: v for k, v in found.items() if v}, "issue numbers in files"
