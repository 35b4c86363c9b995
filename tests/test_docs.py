"""The docs generator (docs/gen/generate.py): the committed docs/_generated/ pages and the README's headline
block are what it writes now, missing results give "not run yet" pages, the nav hook picks up new notes."""

import importlib.util
import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _load(name: str):
    spec = importlib.util.spec_from_file_location(f"docs_gen_{name}", ROOT / "docs" / "gen" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def gen():
    return _load("generate")


def test_generated_docs_and_readme_block_are_current(gen):
    bad = gen.stale()
    assert not bad, "stale generated docs (run: python docs/gen/generate.py): " + ", ".join(bad)


def test_readme_is_short_and_its_headline_links_resolve(gen):
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 250
    block = text.split(gen.BEGIN, 1)[1].split(gen.END, 1)[0]
    links = re.findall(r"\]\(([^)]+)\)", block)
    assert links, "the headline table cites no result file"
    for link in links:
        assert (ROOT / link).is_file(), link
    for link in re.findall(r"\]\((docs/[^)#]+|CHANGELOG\.md|bench/README\.md)(?:#[^)]*)?\)", text):
        assert (ROOT / link).exists(), link


def test_missing_results_say_not_run_yet(gen, tmp_path, monkeypatch):
    monkeypatch.setattr(gen, "RESULTS", tmp_path)
    monkeypatch.setattr(gen, "EXPERIMENTS", tmp_path / "experiments")
    for fam in gen.FAMILIES:
        assert "Not run yet" in gen.experiment(fam)
    assert "Not run yet" in gen.characterization("cnt_pdms")
    assert "Not run yet" in gen.bench_cpu() and "Not run yet" in gen.bench_gpu() and "Not run yet" in gen.bench_streaming()
    assert gen.headline().count("\n") == 2  # header only, no failure


def test_an_unreadable_metrics_file_falls_back_to_its_scalars(gen):
    m = {"mode": "quick", "models": {"tcn": {"test": {"rmse": 0.5, "mae": 0.25, "note": "x"}}}, "findings": {"ok": True}}
    out = gen._generic_report(m)
    assert "| tcn | 0.250 | 0.500 |" in out and "`ok`" in out


def test_parameter_tables_carry_sources(gen):
    text = gen.parameters("cnt_pdms")
    row = next(line for line in text.splitlines() if line.startswith("| `pad.youngs_modulus_pa`"))
    assert "Pa" in row and "1.85e+06" in row
    assert "estimate" in text


def test_notes_hook_adds_unlisted_pages(tmp_path):
    hooks = _load("hooks")
    (tmp_path / "pages").mkdir()
    (tmp_path / "pages" / "cnt.md").write_text("# CNT calibration notes\n\ntext\n")
    (tmp_path / "pages" / "gpu.md").write_text("no heading\n")
    nav = [{"Home": "index.md"}, {"GPU": [{"x": "pages/gpu.md"}]}, {"About these docs": "about-docs.md"}]
    assert hooks.notes(tmp_path, nav) == [{"CNT calibration notes": "pages/cnt.md"}]
    cfg = {"nav": nav, "docs_dir": str(tmp_path)}
    hooks.on_config(cfg)
    assert cfg["nav"][2] == {"Notes": [{"CNT calibration notes": "pages/cnt.md"}]}


def test_notes_hook_drops_nav_entries_of_pages_not_merged_yet(tmp_path):
    hooks = _load("hooks")
    (tmp_path / "pages").mkdir()
    (tmp_path / "pages" / "gpu.md").write_text("# GPU notes\n")
    nav = [{"Real sensors": ["real-sensors.md", {"Import": "pages/import.md"}]},
           {"GPU": ["gpu.md", {"GPU notes": "pages/gpu.md"}]}, {"Only missing": [{"x": "pages/x.md"}]},
           {"Broken elsewhere": "nope.md"}]
    assert hooks.prune(tmp_path, nav) == [{"Real sensors": ["real-sensors.md"]}, {"GPU": ["gpu.md", {"GPU notes": "pages/gpu.md"}]},
                                          {"Broken elsewhere": "nope.md"}]  # outside pages/ strict mode still reports it


def test_characterization_json_has_what_the_page_needs():
    for p in sorted((ROOT / "bench" / "results").glob("characterize-*.json")):
        d = json.loads(p.read_text())
        assert {"title", "columns", "rows", "metrics", "machine"} <= set(d), p.name
        assert all(len(r) == len(d["columns"]) for r in d["rows"]), p.name


def _typed_numbers(text: str) -> list[str]:
    """Table rows of hand-written Markdown that hold a digit outside code spans and link targets."""
    bad = []
    for line in text.splitlines():
        if not line.startswith("|") or re.match(r"^\|[\s|:-]+\|?$", line):
            continue
        bare = re.sub(r"`[^`]*`", "", re.sub(r"\]\([^)]*\)", "]", line))
        if re.search(r"\d", bare):
            bad.append(line)
    return bad


def test_no_hand_typed_numbers_in_tables(gen):
    """Numbers in tables come from docs/gen/generate.py (docs/_generated/, the README block); the notes that other
    branches add under docs/pages/ are theirs and not checked here."""
    pages = [p for p in (ROOT / "docs").rglob("*.md") if not {"_generated", "pages", "gen"} & set(p.relative_to(ROOT / "docs").parts)]
    readme = (ROOT / "README.md").read_text()
    head, rest = readme.split(gen.BEGIN, 1)
    texts = {"README.md": head + rest.split(gen.END, 1)[1]} | {str(p.relative_to(ROOT)): p.read_text() for p in pages}
    bad = {k: _typed_numbers(t) for k, t in texts.items()}
    assert not {k: v for k, v in bad.items() if v}
