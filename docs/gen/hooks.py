"""MkDocs hook (mkdocs.yml `hooks:`) for the notes in docs/pages/, which land from other branches.

* A nav entry that points into docs/pages/ at a file that does not exist (yet) is dropped, so mkdocs.yml can
  place announced pages where they belong before they are merged; everything else in the nav stays strict.
* Every docs/pages/*.md that the nav does not list is added to a "Notes" section, titled by its first `# `
  heading: dropping a page into docs/pages/ is enough to publish it.
"""

from __future__ import annotations

import re
from pathlib import Path

NOTES = "Notes"
FOLDER = "pages"
BEFORE = "About these docs"  # the Notes section goes before this entry


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


def prune(docs_dir: Path, nav: list) -> list:
    """`nav` without the entries that point at a missing docs/<FOLDER>/ file (sections left empty go too)."""
    def gone(target) -> bool:
        return isinstance(target, str) and target.startswith(f"{FOLDER}/") and not (docs_dir / target).is_file()

    out = []
    for item in nav:
        if isinstance(item, dict):
            kept = {}
            for k, v in item.items():
                if isinstance(v, list):
                    v = prune(docs_dir, v)
                    if v:
                        kept[k] = v
                elif not gone(v):
                    kept[k] = v
            if kept:
                out.append(kept)
        elif not gone(item):
            out.append(item)
    return out


def notes(docs_dir: Path, nav) -> list[dict[str, str]]:
    """Nav entries for the pages of docs/<FOLDER>/ that `nav` does not list, sorted by file name."""
    listed = _listed(nav)
    pages = sorted((docs_dir / FOLDER).glob("*.md")) if (docs_dir / FOLDER).is_dir() else []
    return [{_title(p): f"{FOLDER}/{p.name}"} for p in pages if f"{FOLDER}/{p.name}" not in listed]


def on_config(config, **kwargs):
    nav = config.get("nav")
    if nav is None:
        return config
    docs_dir = Path(config["docs_dir"])
    nav[:] = prune(docs_dir, nav)
    extra = notes(docs_dir, nav)
    if extra:
        for item in nav:  # extend an existing Notes section, else insert one before BEFORE
            if isinstance(item, dict) and NOTES in item and isinstance(item[NOTES], list):
                item[NOTES].extend(extra)
                break
        else:
            at = next((i for i, it in enumerate(nav) if isinstance(it, dict) and BEFORE in it), len(nav))
            nav.insert(at, {NOTES: extra})
    return config
