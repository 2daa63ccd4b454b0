"""The documentation site and its code blocks: `mkdocs build --strict` succeeds (a broken link or anchor, a page left
out of the nav or a docstring the API reference cannot render fails it), a built page renders in headless
Chromium, and every fenced code block of docs/*.md runs or is checked, by the convention docs/index.md states:

- ``python`` blocks run, in order, in one temporary working directory and one namespace per page (a block may use
  what an earlier block of its page made); ``<!-- test: check -->`` compiles one instead and checks that what it
  imports exists and its calls' keywords are the callee's parameters;
- ``bash`` blocks are checked: every ``manifoldgen`` command is parsed by the CLI's own parser (click, as typed:
  unknown options, wrong values, missing arguments fail) with its sampler specs, bench methods and ``--set`` keys,
  every ``python SCRIPT`` is parsed by that script's options (its argparse calls, read from its source), every
  ``pip install``
  names existing extras, and every repository path named exists; ``<!-- test: run -->`` also runs them, in the
  page's working directory (``manifoldgen`` in this process, scripts with this Python);
- ``<!-- test: file PATH -->``: the block is copied verbatim from the repository file PATH;
- ``json`` blocks parse (``...`` marks an elision); a constraint spec names a registered type and its parameters,
  and one without elisions is built on its frames' robot and evaluated at that task's home;
  ``toml`` blocks parse; ``text`` blocks are output or a usage line (``<!-- test: usage -->``: checked as bash);
- ``; sub OLD => NEW`` after the action replaces text before running, to run a long example at a test's size;
  ``; skip COMMAND`` leaves one command of a ``run`` block checked only (a server, or a file the page does not make).
"""

from __future__ import annotations

import argparse
import ast
import importlib
import inspect
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = sorted(DOCS.glob("*.md"))
# a word whose first component is one of these names a repository path, which must exist (outputs such as runs/,
# build/ or demo-out/ are not repository paths, even where a local run made them)
REPO_DIRS = {"benchmarks", "docs", "examples", "native", "scripts", "src", "tests"}

OPEN = re.compile(r"^(```|~~~)[ \t]*([\w+-]*)[^\n]*$")
MARKER = re.compile(r"^<!--\s*test:\s*(.*?)\s*-->$")
ACTIONS = {"run", "check", "file", "usage", "output"}


@dataclass
class Block:
    page: Path
    line: int  # 1-based line of the opening fence
    lang: str
    text: str
    action: str = ""
    argument: str = ""
    subs: list[tuple[str, str]] = field(default_factory=list)
    skips: list[str] = field(default_factory=list)  # commands of a run block that are only checked

    @property
    def where(self) -> str:
        page = self.page.relative_to(ROOT).as_posix() if ROOT in self.page.parents else self.page.name
        return f"{page}:{self.line}"

    def code(self) -> str:
        text = self.text
        for old, new in self.subs:
            assert old in text, f"{self.where}: 'sub {old} => {new}': no '{old}' in the block"
            text = text.replace(old, new)
        return text


def blocks(page: Path) -> list[Block]:
    """The page's fenced code blocks (top-level fences), each with the ``<!-- test: ... -->`` marker before it."""
    lines = page.read_text(encoding="utf-8").splitlines()
    found, i = [], 0
    while i < len(lines):
        match = OPEN.match(lines[i])
        if not match:
            i += 1
            continue
        end = next((j for j in range(i + 1, len(lines)) if lines[j].strip() == match.group(1)), None)
        assert end is not None, f"{page.name}:{i + 1}: unclosed code fence"
        block = Block(page, i + 1, match.group(2).lower(), "\n".join(lines[i + 1:end]) + "\n")
        before = next((lines[j].strip() for j in range(i - 1, -1, -1) if lines[j].strip()), "")
        if marker := MARKER.match(before):
            action, *options = [part.strip() for part in marker.group(1).split(";")]
            block.action, _, block.argument = action.partition(" ")
            assert block.action in ACTIONS, f"{block.where}: unknown test action '{block.action}'"
            for option in options:
                if option.startswith("skip "):
                    block.skips.append(option[5:].strip())
                    continue
                assert option.startswith("sub ") and " => " in option, f"{block.where}: unknown option '{option}'"
                old, new = option[4:].split(" => ", 1)
                block.subs.append((old.strip(), new.strip()))
        found.append(block)
        i = end + 1
    return found


ALL = [b for page in PAGES for b in blocks(page)]


# ------------------------------------------------------------------------------------------------------ the site
@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    result = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(ROOT / "mkdocs.yml"),
                             "-d", str(out)], capture_output=True, text=True, env=env, timeout=300)
    assert result.returncode == 0, f"mkdocs build --strict failed:\n{result.stdout}\n{result.stderr}"
    return out


@pytest.mark.slow
def test_the_site_builds_with_warnings_as_errors(site):
    for page in PAGES:
        built = site / ("index.html" if page.stem == "index" else f"{page.stem}/index.html")
        assert built.is_file(), f"{page.name} was not built"
    reference = (site / "api/reference/index.html").read_text(encoding="utf-8")
    import manifoldgen
    for name in manifoldgen.__all__:  # every name of the namespace is documented in the reference
        assert re.search(rf'id="manifoldgen\.[\w.]*\b{name}"', reference), f"mg.{name} is not in the API reference"
    assert ":class:" not in reference and ":func:" not in reference  # docstring roles rendered as code
    for page in PAGES:  # every code block is rendered as one, and the markers before them stay invisible comments
        html = (site / ("index.html" if page.stem == "index" else f"{page.stem}/index.html")).read_text("utf-8")
        article = html.split('<article', 1)[1].split('</article>', 1)[0]
        assert article.count("<pre") == len(blocks(page)), f"{page.name}: a code block did not render as code"
        prose = re.sub(r"<code>.*?</code>", "", article, flags=re.S)  # the convention's own page quotes markers
        assert "&lt;!-- test:" not in prose, f"{page.name}: a test marker is shown as text"


@pytest.mark.slow  # a browser
def test_a_built_page_renders_in_chromium(site, tmp_path):
    browser = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if browser is None:
        pytest.skip("no Chromium on this machine (scripts/setup.sh installs Debian's chromium where it can)")
    from PIL import Image

    width, height = 1280, 900
    shot = tmp_path / "python-api.png"
    result = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                             f"--user-data-dir={tmp_path / 'profile'}", f"--screenshot={shot}",
                             f"--window-size={width},{height}", (site / "python-api/index.html").as_uri()],
                            capture_output=True, text=True, timeout=120)
    assert shot.is_file(), f"no screenshot:\n{result.stderr[-2000:]}"
    image = Image.open(shot).convert("RGB")
    assert image.size == (width, height)
    pixels = image.load()
    # the theme's header bar: one saturated colour along the top edge, unlike the white page below it
    top = [pixels[x, 3] for x in range(0, width, 8)]
    colour = max(set(top), key=top.count)
    assert top.count(colour) > 0.9 * len(top) and max(colour) - min(colour) > 60, f"no coloured header: {colour}"
    assert pixels[640, 300] != colour
    # the page's title "Python API" is drawn: dark pixels in the title region of the content column
    title = [pixels[x, y] for x in range(300, 500) for y in range(95, 140)]
    dark = sum(1 for p in title if sum(p) < 450)
    assert dark > 100, f"the title region is blank ({dark} dark pixels)"
    colours = len(image.getcolors(maxcolors=1 << 20) or [])
    assert colours > 50, f"the page is nearly one flat colour ({colours} colours)"


# ------------------------------------------------------------------------------------------------ the convention
def test_every_block_is_run_or_checked_by_the_convention():
    assert len(ALL) > 30
    for block in ALL:
        if block.action == "file":
            continue
        assert block.lang in {"python", "bash", "json", "toml", "text"}, \
            f"{block.where}: a code block names its language (python, bash, json, toml or text), got '{block.lang}'"
        if block.lang == "text":
            assert block.action in {"output", "usage"}, f"{block.where}: a text block is <!-- test: output --> " \
                                                        "(shown output) or <!-- test: usage --> (a usage line)"
        if block.action == "run":
            assert block.lang in {"python", "bash"}, f"{block.where}: only python and bash blocks run"


def test_the_collector_reads_markers_and_blocks(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("text\n\n<!-- test: run; sub -n 4000 => -n 10; skip manifoldgen view m -->\n\n```bash\n"
                    "manifoldgen sample m -n 4000\n```\n\n```python\nx = 1\n```\n", encoding="utf-8")
    run, plain = blocks(page)
    assert (run.action, run.lang, run.line, run.subs) == ("run", "bash", 5, [("-n 4000", "-n 10")])
    assert run.skips == ["manifoldgen view m"]
    assert run.code() == "manifoldgen sample m -n 10\n"
    assert (plain.action, plain.lang, plain.text) == ("", "python", "x = 1\n")
    assert commands("a \\\n  b  # c\n# d\nT=x; U=y\nmanifoldgen $T 'q r'\nfor m in p q; do c $m; done\n") == \
        [["a", "b"], ["T=x"], ["U=y"], ["manifoldgen", "$T", "q r"], ["c", "p"], ["c", "q"]]
    with pytest.raises(AssertionError, match="(?i)no such option"):
        check_command(Block(page, 1, "bash", ""), ["manifoldgen", "plan", "pose", "--scene", "wall", "--nope"], {})
    with pytest.raises(AssertionError, match="no such file"):
        check_command(Block(page, 1, "bash", ""), ["python", "examples/no_such_checker.py"], {})


# --------------------------------------------------------------------------------------------------- shell blocks
def commands(text: str) -> list[list[str]]:
    """The commands of a shell block: continuation lines joined, comments dropped, ``;`` separating commands, each
    split as the shell does; a one-line ``for V in A B; do ...; done`` loop gives its body once per value."""
    out: list[list[str]] = []
    for line in text.replace("\\\n", " ").splitlines():
        lexer = shlex.shlex(line, posix=True, punctuation_chars=";")
        lexer.whitespace_split = True
        statements, words = [], []
        for token in lexer:
            if token == ";":
                statements.append(words)
                words = []
            else:
                words.append(token)
        statements = [w for w in [*statements, words] if w]
        if statements and statements[0][:1] == ["for"]:
            variable, values = statements[0][1], statements[0][3:]
            assert statements[0][2] == "in" and statements[1][0] == "do" and statements[-1] == ["done"], line
            body = [statements[1][1:], *statements[2:-1]]
            statements = [[re.sub(rf"\$({variable}\b|{{{variable}}})", value, w) for w in words]
                          for value in values for words in body]
        out.extend(statements)
    return out


def expand(words: list[str], env: dict) -> list[str]:
    return [re.sub(r"\$(\w+)|\$\{(\w+)\}", lambda m: env[m.group(1) or m.group(2)], w) for w in words]


def repo_paths(word: str) -> list[str]:
    """The repository paths a word names (itself, or the parts of a spec like ``cvae:src/...,batch=64``)."""
    parts = re.split(r"[:,=|\[\]]", word)
    return [p for p in parts if "/" in p and p.split("/")[0] in REPO_DIRS]


def cli_command(block: Block, args: list[str]):
    """The click command ``manifoldgen ARGS`` reaches (its names from the top, e.g. ``["bench", "plan"]``), and its
    context parsed from ``ARGS`` strictly."""
    import typer

    from manifoldgen.cli import app

    command = typer.main.get_command(app)
    ctx = command.make_context("manifoldgen", [], resilient_parsing=True)
    names = []
    while hasattr(command, "get_command"):  # a group (typer's own click or click's)
        assert args, f"{block.where}: manifoldgen {' '.join(names)}: no subcommand"
        sub = command.get_command(ctx, args[0])
        assert sub is not None, f"{block.where}: no command '{args[0]}' in manifoldgen {' '.join(names)}"
        command, args = sub, args[1:]
        names.append(command.name)
    if "..." in args:  # elided arguments: check only that every option exists
        options = {name for p in command.params for name in (*p.opts, *p.secondary_opts)}
        for word in args:
            if word.startswith("-") and word != "-":
                assert word.split("=")[0] in options, f"{block.where}: {command.name}: no such option {word}"
        return names, None
    try:
        ctx = command.make_context(command.name, list(args), parent=ctx, resilient_parsing=False)
    except Exception as exc:  # a usage error of click (typer carries its own copy of click)
        if not hasattr(exc, "format_message"):
            raise
        raise AssertionError(f"{block.where}: manifoldgen ... {command.name} {' '.join(args)}: "
                             f"{exc.format_message()}") from exc
    return names, ctx


def check_cli_values(block: Block, names: list[str], ctx) -> None:
    """The values the CLI would check only when running: sampler specs, bench methods, --set keys."""
    from manifoldgen.bench.planning import BLIND, FEET_ONLY, Method
    from manifoldgen.planning import PLANNERS, planner_settings
    from manifoldgen.settings import parse_settings
    from manifoldgen.specs import parse_spec

    def sampler(spec: str) -> None:
        from manifoldgen.models import MODELS

        name, argument, _ = parse_spec(spec)
        known = {"uniform", "project", "pg", "model", *MODELS.names()}
        assert name in known, f"{block.where}: sampler '{spec}': no sampler '{name}' (known: {sorted(known)})"
        assert bool(argument) == (name not in {"uniform", "project"}) or name == "pg", f"{block.where}: '{spec}'"

    params = ctx.params
    if params.get("sampler"):
        sampler(params["sampler"])
    for method in params.get("methods") or []:
        parsed = Method.parse(method)
        if parsed.sampler and parsed.sampler not in (BLIND, FEET_ONLY):
            sampler(parsed.sampler)
    if params.get("settings") and names == ["plan"]:
        parse_settings(params["settings"], None, planner_settings(params["planner"]), "planner")
    elif params.get("settings") and names[0] == "bench":  # any planner's settings, and OMPL's ompl_KEY (as the CLI)
        from manifoldgen.ompl_settings import benchmark_keys
        known = {**{k: v for name in PLANNERS.names() for k, v in planner_settings(name).items()}, **benchmark_keys()}
        parse_settings(params["settings"], None, known, "planner")
    if params.get("settings") and names == ["train"] and params.get("model") not in (None, "auto"):
        from manifoldgen.models import get_model_class
        parse_settings(params["settings"], None, get_model_class(params["model"]).defaults, "model")


class _ParseError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # raise instead of printing usage and exiting
        raise _ParseError(message)


def script_parser(script: Path) -> argparse.ArgumentParser | set[str]:
    """The script's argparse parser rebuilt from its source (nothing is run): every ``add_argument`` with its
    option strings and its literal ``nargs``, ``action``, ``choices``, ``required`` and builtin ``type``. A script
    with subcommands gives the set of its option strings instead."""
    tree = ast.parse(script.read_text(encoding="utf-8"))
    calls = [node for node in ast.walk(tree) if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)]
    adds = sorted((c for c in calls if c.func.attr == "add_argument"), key=lambda c: (c.lineno, c.col_offset))
    if any(c.func.attr == "add_subparsers" for c in calls):
        return {a.value for c in adds for a in c.args if isinstance(a, ast.Constant) and str(a.value).startswith("-")}
    parser = _Parser(prog=script.name, add_help=True)
    for call in adds:
        names = [a.value for a in call.args if isinstance(a, ast.Constant)]
        options = {}
        for keyword in call.keywords:
            if keyword.arg in {"nargs", "action", "choices", "required", "dest", "const"}:
                try:
                    options[keyword.arg] = ast.literal_eval(keyword.value)
                except ValueError:  # not a literal (choices=list(ROBOTS), a custom action): not checked
                    pass
            elif keyword.arg == "type" and isinstance(keyword.value, ast.Name) and keyword.value.id in {"int", "float"}:
                options["type"] = {"int": int, "float": float}[keyword.value.id]
        if options.get("action") in {"store_true", "store_false", "count", "help", "version"}:
            options.pop("type", None)
        parser.add_argument(*names, **options)
    return parser


def check_script(block: Block, script: Path, args: list[str]) -> None:
    """``python SCRIPT ARGS``: parsed by the script's own options (see :func:`script_parser`)."""
    parser = script_parser(script)
    name = script.relative_to(ROOT).as_posix()
    if isinstance(parser, set):
        for word in args:
            if re.match(r"--?[a-zA-Z]", word):
                assert word.split("=")[0] in parser, f"{block.where}: {name} has no option {word}"
        return
    try:
        parser.parse_args(args)
    except _ParseError as exc:
        raise AssertionError(f"{block.where}: python {name} {shlex.join(args)}: {exc}") from exc


def check_command(block: Block, words: list[str], env: dict) -> None:
    """One shell command, checked without running it (see the module docstring)."""
    while words and re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S*", words[0]):  # VAR=value prefixes (or a bare assignment)
        name, _, value = words.pop(0).partition("=")
        if not words:
            env[name] = value
            return
        assert name in env or name.startswith("MANIFOLDGEN_") and (
            name in (ROOT / "pyproject.toml").read_text() or name in (ROOT / "native/CMakeLists.txt").read_text()), \
            f"{block.where}: {name} is not a variable the build or the package reads"
    words = expand(words, env)
    for word in words:
        for path in repo_paths(word):
            assert (ROOT / path).exists(), f"{block.where}: {path}: no such file or folder in the repository"
    program, args = words[0], words[1:]
    program = re.sub(r"^[\w.-]+/bin/(?=pip$|python$|manifoldgen$)", "", program)  # a virtual environment's tools
    if program == "manifoldgen":
        names, ctx = cli_command(block, args)
        if ctx is not None:
            check_cli_values(block, names, ctx)
    elif program in {"python", "python3"}:
        if args[:1] == ["-m"]:
            assert args[1] in {"pytest", "pip", "mkdocs", "build", "venv"}, f"{block.where}: python -m {args[1]}"
            return
        script = ROOT / args[0]
        assert script.is_file(), f"{block.where}: {args[0]}: no such file"
        if block.action == "usage":  # a usage line: [OPTIONAL ...] brackets, placeholders, alternatives
            parser = script_parser(script)
            known = parser if isinstance(parser, set) else {o for a in parser._actions for o in a.option_strings}
            for word in (w.strip("[]") for w in args[1:]):
                if re.match(r"--?[a-zA-Z]", word):
                    assert word in known, f"{block.where}: {args[0]} has no option {word}"
        else:
            check_script(block, script, args[1:])
    elif program == "pip":
        assert args[0] == "install", f"{block.where}: pip {args[0]}"
        project = tomllib.loads((ROOT / "pyproject.toml").read_text())
        extras = project["project"]["optional-dependencies"]
        build = " ".join(project["build-system"]["requires"])
        for word in args[1:]:
            if word.startswith("-C"):
                define = re.fullmatch(r"-C\s*cmake\.define\.(\w+)=\w+", word)
                if define:
                    assert define.group(1) in (ROOT / "native/CMakeLists.txt").read_text(), \
                        f"{block.where}: {word}: no such CMake option in native/CMakeLists.txt"
            elif word.startswith("-"):
                assert word in {"-e", "--no-build-isolation", "--no-deps", "--force-reinstall"}, \
                    f"{block.where}: pip option {word}"
            elif word.startswith("."):
                named = re.fullmatch(r"\.(?:\[([\w,]+)\])?", word)
                assert named, f"{block.where}: pip install {word}"
                for extra in (named.group(1) or "").split(","):
                    assert not extra or extra in extras, f"{block.where}: no extra [{extra}] in pyproject.toml"
            elif word.endswith(".tar.gz"):  # the source distribution `python -m build --sdist` makes
                version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
                assert word.endswith(f"manifoldgen-{version}.tar.gz"), f"{block.where}: {word} is not this sdist"
            elif word.startswith("torch=="):
                assert word in (ROOT / "scripts/setup.sh").read_text(), f"{block.where}: {word} is not setup.sh's"
            else:  # the core's rebuild: the build requirements, without the pinned pin
                assert word in build, f"{block.where}: {word} is not a build requirement in pyproject.toml"
    elif program == "mkdocs":
        assert args[0] in {"serve", "build"} and (ROOT / "mkdocs.yml").is_file(), f"{block.where}: mkdocs {args[0]}"
    elif program == "bash":
        assert (ROOT / args[0]).is_file(), f"{block.where}: {args[0]}: no such file"
    elif program == "ray":  # Ray's own command line, for a cluster of several machines (the [ray] extra)
        assert args[0] in {"start", "stop", "status"}, f"{block.where}: ray {args[0]}"
    else:
        raise AssertionError(f"{block.where}: no check for the command '{program}' (see tests/test_docs.py)")


def run_command(block: Block, words: list[str], env: dict, cwd: Path) -> None:
    """One shell command of a ``run`` block, run in ``cwd`` after its check."""
    check_command(block, list(words), env)
    while words and re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S*", words[0]):
        if len(words) == 1:
            return
        words = words[1:]
    words = expand(words, env)
    words = [str(ROOT / w) if w.split("/")[0] in REPO_DIRS and (ROOT / w).exists() else w for w in words]
    if words[0] == "manifoldgen":
        from typer.testing import CliRunner

        from manifoldgen.cli import app

        result = CliRunner().invoke(app, words[1:])
        assert result.exit_code == 0, f"{block.where}: {shlex.join(words)}: exit {result.exit_code}\n" \
                                      f"{result.output[-3000:]}"
    elif words[0] == "python":
        result = subprocess.run([sys.executable, *words[1:]], cwd=cwd, capture_output=True, text=True, timeout=120)
        assert result.returncode == 0, f"{block.where}: {shlex.join(words)}: exit {result.returncode}\n" \
                                       f"{result.stdout[-3000:]}{result.stderr[-3000:]}"
    else:
        raise AssertionError(f"{block.where}: a run block runs manifoldgen and python commands only")


# -------------------------------------------------------------------------------------------------- python blocks
def return_type(function) -> type | None:
    """The class ``function`` is annotated to return (a name in its module: annotations may be strings)."""
    try:
        annotation = inspect.signature(function).return_annotation
    except (TypeError, ValueError):
        return None
    if isinstance(annotation, str):
        annotation = vars(sys.modules[function.__module__]).get(annotation)
    return annotation if isinstance(annotation, type) else None


def check_python(block: Block) -> None:
    """Compile a python block; what it imports must exist, its calls' keywords must be the callee's parameters,
    and attributes read off a call's result must exist on the callee's annotated return type."""
    tree = ast.parse(block.code(), filename=block.where)
    names: dict[str, object] = {}
    returned: dict[str, type] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            module = importlib.import_module(node.module)
            for alias in node.names:
                assert hasattr(module, alias.name), f"{block.where}: {node.module} has no {alias.name}"
                names[alias.asname or alias.name] = getattr(module, alias.name)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                names[alias.asname or alias.name] = importlib.import_module(alias.name)
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in names:
            callee = names[node.func.id]
            signature = inspect.signature(callee)
            try:
                signature.bind_partial(*node.args, **{k.arg: None for k in node.keywords if k.arg})
            except TypeError as exc:
                raise AssertionError(f"{block.where}: {node.func.id}(...): {exc}") from exc
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call) and \
                isinstance(node.value.func, ast.Name) and node.value.func.id in names:
            kind = return_type(names[node.value.func.id])
            if kind is not None:
                for target in node.targets:
                    if isinstance(target, ast.Name):
                        returned[target.id] = kind
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in returned:
            cls = returned[node.value.id]
            fields = getattr(cls, "__dataclass_fields__", {})
            assert node.attr in fields or hasattr(cls, node.attr), \
                f"{block.where}: {cls.__name__} has no attribute {node.attr}"


# ---------------------------------------------------------------------------------------------- data-file blocks
def check_json(block: Block) -> None:
    text = re.sub(r",\s*\.\.\.", "", block.text)  # "[1, 2, ...]" and '{"type": "x", ...}': elisions
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise AssertionError(f"{block.where}: not JSON: {exc}") from exc
    if isinstance(doc, dict) and "type" in doc:
        check_constraint_spec(block, doc, elided=text != block.text)


def check_constraint_spec(block: Block, spec: dict, elided: bool) -> None:
    from manifoldgen.constraints import CONSTRAINTS

    cls = CONSTRAINTS.get(spec["type"])
    if spec["type"] == "set":
        assert set(spec) == {"type", "parts"}, f"{block.where}: a set has parts only"
        for part in spec["parts"]:
            check_constraint_spec(block, part, elided)
        return
    params = inspect.signature(cls.__init__).parameters
    given = set(spec) - {"type"}
    unknown = given - set(params)
    assert not unknown, f"{block.where}: constraint '{spec['type']}' has no parameters {sorted(unknown)}"
    required = {n for n, p in params.items() if p.default is p.empty and n not in ("self", "robot")
                and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)}
    assert elided or required <= given, f"{block.where}: constraint '{spec['type']}' needs {sorted(required - given)}"
    if not elided:  # built on the robot its frames belong to, and evaluated at that task's home
        build_on_robot(block, spec)


# which built-in task's robot a spec's frames belong to (by frame name); a spec without frames: panda's 7 joints
ROBOT_TASKS = {"panda_": ("pose", "panda"), "r_gripper": ("dualarm", "pr2"), "l_gripper": ("dualarm", "pr2"),
               "point": ("sphere", None)}


def build_on_robot(block: Block, spec: dict) -> None:
    import numpy as np

    from manifoldgen.constraints import build_constraint
    from manifoldgen.tasks import get_task

    frames = [v for k, v in spec.items() if k == "frame" or k.startswith("frame_")]
    tasks = {task for prefix, task in ROBOT_TASKS.items() for f in frames if f.startswith(prefix)}
    tasks = tasks or {("pose", "panda")}
    assert len(tasks) == 1, f"{block.where}: frames {frames} of no single known robot"
    task = get_task(*tasks.pop())
    constraint = build_constraint(task.robot, spec)
    y = np.asarray(constraint.condition.values, float)[:1]
    residual = constraint.residual(task.home[None], y)
    assert residual.shape == (1, len(constraint.tolerance)), f"{block.where}: residual {residual.shape}"


# ----------------------------------------------------------------------------------------------------- the tests
@pytest.mark.parametrize("block", [b for b in ALL if b.action == "file"], ids=lambda b: b.where)
def test_a_block_copied_from_a_file_is_the_file(block):
    file = ROOT / block.argument
    assert file.is_file(), f"{block.where}: {block.argument}: no such file"
    assert block.text.strip() in file.read_text(encoding="utf-8"), \
        f"{block.where}: the block is no longer a verbatim part of {block.argument}"


@pytest.mark.parametrize("block", [b for b in ALL if b.action != "file" and b.lang in {"json", "toml"}],
                         ids=lambda b: b.where)
def test_data_blocks_parse(block):
    if block.lang == "json":
        check_json(block)
    else:
        tomllib.loads(block.text)


@pytest.mark.parametrize("block", [b for b in ALL if b.action in {"", "check", "usage"} and b.lang in
                                   {"bash", "text", "python"} and not (b.lang == "python" and b.action == "")],
                         ids=lambda b: b.where)
def test_checked_blocks_are_valid(block):
    if block.lang == "python":
        check_python(block)
        return
    env: dict[str, str] = {}
    for words in commands(block.code()):
        check_command(block, words, env)


@pytest.mark.slow  # collects, trains and plans (seconds each)
@pytest.mark.parametrize("page", [p for p in PAGES if any(b.action == "run" or (b.lang == "python" and not b.action)
                                                          for b in blocks(p))], ids=lambda p: p.name)
def test_the_pages_examples_run(page, tmp_path, monkeypatch):
    """The page's running blocks, in order, in one working directory (python blocks share one namespace)."""
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__docs__"}
    env: dict[str, str] = {}
    for block in blocks(page):
        if block.lang == "python" and block.action in {"", "run"}:
            exec(compile(block.code(), block.where, "exec"), namespace)
        elif block.lang == "bash" and block.action == "run":
            skipped = set()
            for words in commands(block.code()):
                if shlex.join(words) in block.skips:
                    check_command(block, words, env)
                    skipped.add(shlex.join(words))
                else:
                    run_command(block, words, env, tmp_path)
            assert skipped == set(block.skips), f"{block.where}: 'skip' names no command: {set(block.skips) - skipped}"
