"""Build-time hooks of the docs site (mkdocs.yml `hooks:`), so that nothing on it is typed twice.

- The CLI reference page is written from `mjx-pusht`'s own argparse parser at every build: a flag added,
  renamed or re-documented in the parser is on the site the next time it is built.
- Pages link to the repository's committed results (`../outputs/reports/...`, `../benchmarks/results/...`)
  by their path in the repository, so the links also work where the Markdown is read on its own. Those
  files are copied into the site and the links pointed at the copies; a link to a file that is not in the
  repository stays as written, and `mkdocs build --strict` fails on it like on any broken link.
- Every `docs/notebook/<branch>.md` (a branch's lab-notebook entry) is listed under "Lab notebook".
- "notebook change N" in a page's prose links to that change's entry in the lab notebook.
- The API reference has a page for every package of mjx_pusht, found at build time: a package added or
  renamed gets its page (and its nav entry) without an edit here.
"""

from __future__ import annotations

import argparse
import posixpath
import re
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]
CLI_MARKER = "<!-- cli-reference -->"
# a Markdown link or image target: ](target) or ](target "title"); code spans and fences are stripped first
_LINK = re.compile(r"\]\(([^()\s]+)(?:\s+\"[^\"]*\")?\)")
_CODE = re.compile(r"```.*?```|`[^`\n]*`", re.S)
_FOREIGN = re.compile(r"^[a-z][a-z0-9+.-]*:|^#|^/")  # a URL, an anchor on the same page, an absolute path


def _targets(markdown: str):
    for m in _LINK.finditer(_CODE.sub("", markdown)):
        target = m.group(1).split("#", 1)[0]
        if target and not _FOREIGN.match(target):
            yield target


def _outside(page_uri: str, target: str, docs_rel: str) -> str | None:
    """The repository path a page's link points to when it leaves docs/, else None."""
    path = posixpath.normpath(posixpath.join(docs_rel, posixpath.dirname(page_uri), target))
    if path.startswith("../") or path == docs_rel or path.startswith(docs_rel + "/"):
        return None
    return path


API_MARKER = "<!-- api-packages -->"


def packages() -> list[str]:
    """mjx_pusht's packages (folders with an __init__.py), by name."""
    return sorted(p.parent.name for p in (ROOT / "mjx_pusht").glob("*/__init__.py"))


def _api_nav(items) -> None:
    """Expand the nav's "API" entry into its index and a page per package."""
    for item in items or []:
        if not isinstance(item, dict):
            continue
        for key, value in item.items():
            if key == "API" and isinstance(value, str):
                item[key] = [value] + [{p: f"api/{p}.md"} for p in packages()]
            elif isinstance(value, list):
                _api_nav(value)


def on_config(config):
    """Give the nav a page per package under "API", and docs/notebook/*.md under "Lab notebook"."""
    _api_nav(config["nav"])
    folder = Path(config["docs_dir"]) / "notebook"
    entries = sorted(f"notebook/{p.name}" for p in folder.glob("*.md")) if folder.is_dir() else []
    for i, item in enumerate(config["nav"] or []):
        if entries and isinstance(item, dict) and "Lab notebook" in item:
            head = item["Lab notebook"]
            item["Lab notebook"] = ([head] if isinstance(head, str) else list(head)) + entries
            config["nav"][i] = item
    return config


def on_files(files, config):
    """Add the repository files that pages link to outside docs/ (and what those link to, if Markdown)."""
    docs_dir = Path(config["docs_dir"]).resolve()
    docs_rel = docs_dir.relative_to(ROOT).as_posix()
    queue = [(f.src_uri, Path(f.abs_src_path)) for f in files.documentation_pages()]
    added: set[str] = set()
    while queue:
        uri, path = queue.pop()
        for target in _targets(path.read_text(encoding="utf-8")):
            repo_path = _outside(uri, target, docs_rel) if path.is_relative_to(docs_dir) else \
                posixpath.normpath(posixpath.join(posixpath.dirname(uri), target))
            if repo_path is None or repo_path in added or not (ROOT / repo_path).is_file():
                continue
            added.add(repo_path)
            files.append(File(repo_path, str(ROOT), config["site_dir"], config["use_directory_urls"]))
            if repo_path.endswith(".md"):
                queue.append((repo_path, ROOT / repo_path))
    config["_repo_files"] = added
    for p in packages():  # the API pages: one a package, written here unless docs/ has one of its own
        if files.get_file_from_path(f"api/{p}.md") is None:
            files.append(File.generated(config, f"api/{p}.md", content=f"# `mjx_pusht.{p}`\n\n::: mjx_pusht.{p}\n"
                                        "    options:\n      show_root_heading: false\n"))
    return files


_CHANGE = re.compile(r"\bnotebook(,?) (changes?) (\d+)")
_HEADING = re.compile(r"^## .*\bchange (\d+)\b.*$", re.M)


def _change_anchors(docs_dir: Path) -> dict[str, str]:
    """Each lab-notebook change's heading anchor, as the toc extension makes it from the heading's text."""
    from markdown.extensions.toc import slugify

    text = (docs_dir / "notebook.md").read_text(encoding="utf-8")
    anchors = {}
    for m in _HEADING.finditer(text):
        title = re.sub(r"[`*]", "", m.group(0)[3:]).strip()
        anchors.setdefault(m.group(1), slugify(title, "-"))
    return anchors


def on_page_markdown(markdown, page, config, files):
    docs_rel = Path(config["docs_dir"]).resolve().relative_to(ROOT).as_posix()
    if page.file.src_uri != "notebook.md" and _CHANGE.search(markdown):
        anchors = _change_anchors(Path(config["docs_dir"]))
        to = posixpath.relpath("notebook.md", posixpath.dirname(page.file.src_uri) or ".")

        def change(m):
            anchor = anchors.get(m.group(3))
            return f"[notebook{m.group(1)} {m.group(2)} {m.group(3)}]({to}#{anchor})" if anchor else m.group(0)

        parts = re.split(r"(```.*?```|`[^`\n]*`|\[[^\]]*\]\([^)]*\))", markdown, flags=re.S)
        markdown = "".join(p if p.startswith(("`", "[")) else _CHANGE.sub(change, p) for p in parts)
    if CLI_MARKER in markdown:
        markdown = markdown.replace(CLI_MARKER, cli_reference())
    if API_MARKER in markdown:
        markdown = markdown.replace(API_MARKER, "\n".join(f"- [`mjx_pusht.{p}`]({p}.md)" for p in packages()))
    if not page.file.abs_src_path or not Path(page.file.abs_src_path).resolve().is_relative_to(ROOT / docs_rel):
        return markdown  # a copied repository file: its links are already relative to its own place
    added = config.get("_repo_files", set())

    def point(m):
        whole, target = m.group(0), m.group(1)
        path, _, anchor = target.partition("#")
        repo_path = _outside(page.file.src_uri, path, docs_rel) if path and not _FOREIGN.match(path) else None
        if repo_path not in added:
            return whole
        new = posixpath.relpath(repo_path, posixpath.dirname(page.file.src_uri) or ".") + (f"#{anchor}" if anchor else "")
        return whole.replace(target, new, 1)

    # rewrite outside code: split on code spans and fences, rewrite the prose parts only
    parts = re.split(r"(```.*?```|`[^`\n]*`)", markdown, flags=re.S)
    return "".join(p if p.startswith("`") else _LINK.sub(point, p) for p in parts)


def _flags(action: argparse.Action) -> str:
    if not action.option_strings:
        return f"`{action.metavar or action.dest}`"
    metavar = ""
    if action.nargs != 0:
        mv = action.metavar or ("{" + "|".join(map(str, action.choices)) + "}" if action.choices else action.dest.upper())
        metavar = " " + " ".join(mv) if isinstance(mv, tuple) else f" {mv}"
    return ", ".join(f"`{o}{metavar}`" for o in action.option_strings)


def _default(action: argparse.Action) -> str:
    d = action.default
    if action.nargs == 0 or d is None or d is argparse.SUPPRESS or d == []:
        return ""
    if isinstance(d, tuple):
        d = ",".join(map(str, d))
    return f"`{d}`"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ").replace("%%", "%")


def cli_reference() -> str:
    """Every `mjx-pusht` command and flag, read from the parser the command line itself uses."""
    from mjx_pusht.cli.parser import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {c.dest: c.help for c in sub._choices_actions}
    out = [f"`mjx-pusht [--verbose] COMMAND ...` (or `python -m mjx_pusht ...`): {parser.description}", ""]
    glob = [a for a in parser._actions if a.option_strings and not isinstance(a, argparse._HelpAction)]
    out += ["| global flag | default | what it does |", "| --- | --- | --- |"]
    out += [f"| {_flags(a)} | {_default(a)} | {_cell(a.help or '')} |" for a in glob]
    for name, p in sub.choices.items():
        out += ["", f"## `mjx-pusht {name}`", "", _cell(helps.get(name) or ""), ""]
        out += ["| flag | default | what it does |", "| --- | --- | --- |"]
        for a in p._actions:
            if isinstance(a, argparse._HelpAction):
                continue
            out.append(f"| {_flags(a)} | {_default(a)} | {_cell(a.help or '')} |")
    return "\n".join(out) + "\n"
