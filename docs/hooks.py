"""MkDocs hook: links from the pages to repository files outside docs/ (the README, examples/, benchmarks/,
src/...). On GitHub they work as relative links; the site holds only docs/, so there such a link becomes a link to
the file in the repository when mkdocs.yml sets ``repo_url``, and otherwise its text followed by the file's
repository path in code. A link to a repository file that does not exist is a warning (an error under
``--strict``)."""

from __future__ import annotations

import logging
import re
from pathlib import Path

log = logging.getLogger("mkdocs.hooks.repository_links")

FENCE = re.compile(r"^[ \t]*(```|~~~)[^\n]*\n.*?^[ \t]*\1[ \t]*$", re.S | re.M)
CODE_SPAN = re.compile(r"(`+).+?\1", re.S)
LINK = re.compile(r"(?<!!)\[((?:[^\[\]]|\[[^\[\]]*\])*)\]\(\s*<?([^)\s>]*)>?\s*\)")
SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")


def _outside(target: str, page_dir: Path, docs: Path, root: Path) -> tuple[Path, str] | None:
    """``(repository-relative path, '#fragment' or '')`` when ``target`` leaves docs/, else None."""
    if not target or SCHEME.match(target) or target.startswith("#"):
        return None
    path, _, fragment = target.partition("#")
    file = (page_dir / path).resolve()
    if file == docs or docs in file.parents:
        return None
    return file.relative_to(root) if root in file.parents or file == root else file, f"#{fragment}" if fragment else ""


def on_page_markdown(markdown: str, page, config, files) -> str:
    docs = Path(config["docs_dir"]).resolve()
    root = docs.parent
    page_dir = (docs / page.file.src_path).parent
    repo_url = (config.get("repo_url") or "").rstrip("/")

    def rewrite(match: re.Match) -> str:
        text, target = match.group(1), match.group(2)
        outside = _outside(target, page_dir, docs, root)
        if outside is None:
            return match.group(0)
        relative, fragment = outside
        if relative.is_absolute() or not (root / relative).exists():
            log.warning("%s: link to %s: no such file in the repository", page.file.src_path, target)
            return match.group(0)
        name = relative.as_posix() + ("/" if (root / relative).is_dir() else "")
        if repo_url:
            kind = "tree" if (root / relative).is_dir() else "blob"
            return f"[{text}]({repo_url}/{kind}/main/{relative.as_posix()}{fragment})"
        if text.strip("`") in (name, name.rstrip("/")):  # the link's text is the path itself
            return f"`{name}`"
        return text if f"`{name}`" in text or f"`{name.rstrip('/')}`" in text else f"{text} (`{name}`)"

    def prose(segment: str) -> str:
        spans = [m.span() for m in CODE_SPAN.finditer(segment)]  # no links inside code spans

        def outside_code(match: re.Match) -> str:
            inside = any(start <= match.start() < end for start, end in spans)
            return match.group(0) if inside else rewrite(match)
        return LINK.sub(outside_code, segment)

    out, last = [], 0
    for fence in FENCE.finditer(markdown):
        out.append(prose(markdown[last:fence.start()]))
        out.append(fence.group(0))
        last = fence.end()
    out.append(prose(markdown[last:]))
    return "".join(out)


# The docstrings are written for Sphinx-style readers (":class:`~manifoldgen.errors.ManifoldgenError`"); the API
# reference renders the role's target as code, linked when the page documents it, instead of the bare role.
ROLE = re.compile(r":(?:py:)?(?:class|func|meth|attr|mod|data|exc|obj|const):<code>(~?)([\w.]+)(\(\))?</code>")


def on_page_content(html: str, page, config, files) -> str:
    ids = set(re.findall(r'id="([\w.]+)"', html))

    def role(match: re.Match) -> str:
        short, name, call = match.group(1), match.group(2), match.group(3) or ""
        shown = (name.rsplit(".", 1)[-1] if short else name) + call
        target = name if name in ids else next((i for i in ids if i.endswith("." + name)), None)
        code = f"<code>{shown}</code>"
        return f'<a href="#{target}">{code}</a>' if target else code
    return ROLE.sub(role, html)
