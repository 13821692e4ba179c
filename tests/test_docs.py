"""The README and the committed results read as the docs promise: short, every link there, no machine's paths.

The docs site itself is checked by `make docs` (mkdocs build --strict: links, anchors, API references), in CI."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_readme_is_short_and_each_of_its_links_is_a_file_or_folder_of_the_repository():
    text = (ROOT / "README.md").read_text()
    assert len(text.encode()) < 15_000
    targets = [t.split("#")[0] for t in re.findall(r"\]\(([^)\s]+)\)", text)]
    local = [t for t in targets if t and not re.match(r"[a-z]+:", t)]
    assert local, "the README links its docs"
    assert [t for t in local if not (ROOT / t).exists()] == []


def test_committed_logs_and_summaries_name_no_machines_absolute_paths():
    found = []
    for path in (ROOT / "outputs").rglob("*"):
        if not path.is_file() or path.suffix in (".parquet", ".rrd", ".msgpack", ".png", ".gif"):
            continue
        try:
            text = path.read_text()
        except UnicodeDecodeError:
            continue
        found += [f"{path.relative_to(ROOT)}: {m.group(0)}" for m in re.finditer(r"(?<![\w.])/(root|home|work|tmp)/\S*", text)]
    assert found == []


def test_each_relative_link_of_the_docs_site_is_a_file_not_a_folder():
    """mkdocs build --strict (CI's `make test`) fails on a link to a folder: caught here in the fast loop."""
    bad = []
    for page in (ROOT / "docs").rglob("*.md"):
        for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text()):
            target = target.split("#")[0]
            if target and not re.match(r"[a-z]+:", target) and not (page.parent / target).is_file():
                bad.append(f"{page.relative_to(ROOT)}: {target}")
    assert bad == []
