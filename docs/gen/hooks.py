"""MkDocs hook (mkdocs.yml `hooks:`): every docs/pages/*.md that the nav does not list yet is added to a
"Notes" section, titled by its first `# ` heading. Dropping a page into docs/pages/ is enough to publish it;
to show it elsewhere (under a family, say), list it in mkdocs.yml's nav and the hook leaves it there."""

from __future__ import annotations

import re
from pathlib import Path

NOTES = "Notes"
FOLDER = "pages"


def _listed(nav) -> set[str]:
    out: set[str] = set()
    for item in nav or []:
        if isinstance(item, str):
            out.add(item)
        elif isinstance(item, dict):
            for v in item.values():
                out |= _listed(v) if isinstance(v, list) else ({v} if isinstance(v, str) else set())
    return out


def _title(path: Path) -> str:
    for line in path.read_text(encoding="utf-8").splitlines():
        m = re.match(r"^#\s+(.+?)\s*#*\s*$", line)
        if m:
            return m.group(1)
    return path.stem.replace("_", " ").replace("-", " ")


def notes(docs_dir: Path, nav) -> list[dict[str, str]]:
    """Nav entries for the pages of docs/<FOLDER>/ that `nav` does not list, sorted by file name."""
    listed = _listed(nav)
    pages = sorted((docs_dir / FOLDER).glob("*.md")) if (docs_dir / FOLDER).is_dir() else []
    return [{_title(p): f"{FOLDER}/{p.name}"} for p in pages if f"{FOLDER}/{p.name}" not in listed]


def on_config(config, **kwargs):
    nav = config.get("nav")
    if nav is None:
        return config
    extra = notes(Path(config["docs_dir"]), nav)
    if extra:
        for item in nav:  # extend an existing Notes section, else insert one before "About these docs"
            if isinstance(item, dict) and NOTES in item and isinstance(item[NOTES], list):
                item[NOTES].extend(extra)
                break
        else:
            at = next((i for i, it in enumerate(nav) if isinstance(it, dict) and "About these docs" in it), len(nav))
            nav.insert(at, {NOTES: extra})
    return config
