"""The source papers are cited by author and title wherever a user reads: the README, the
CLI help, `brdfbench list` (every plugin spec's text) and the leaderboards, Markdown and
HTML, written from a small store. The internal labels the published-figures data are keyed
by never reach any of them; the README keeps the one reference list."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from brdfbench import citations, cli
from brdfbench.plugins import registry
from brdfbench.report import write_reports
from brdfbench.store.sqlite import ConfigRecord, ResultsStore, Row
from brdfbench_leaderboard import published

ROOT = Path(__file__).resolve().parents[2]
#: An internal label in any spelling, a line break included ("seed\n003").
LABEL = re.compile(r"seed[\s_-]*00[0-3]", re.IGNORECASE)


def _hits(text: str, where: str) -> list[str]:
    lines = text.splitlines()
    out = []
    for m in LABEL.finditer(text):
        n = text.count("\n", 0, m.start())
        out.append(f"{where}:{n + 1}: {lines[n].strip()[:120]}")
    return out


def test_the_mapping_covers_the_four_papers_and_every_spelling():
    assert [p.short for p in citations.PAPERS.values()] == ["Hu 2026", "Sztrajman et al. 2021", "Timonen et al.",
                                                           "Zhou et al."]
    assert citations.source("seed 001 (Sztrajman et al., Neural BRDF, CGF 2021)") == "Sztrajman et al. 2021"
    assert citations.cite("as seed 003's Table 1, and Seed-002 Eq. 7, seed_000 §3.1.1") == (
        "as Zhou et al.'s Table 1, and Timonen et al. Eq. 7, Hu 2026 §3.1.1")
    assert citations.paper("SEED002").title.startswith("A Real-Time Multi-Scale")
    with pytest.raises(KeyError, match="not a source paper"):
        citations.paper("seed 004")


def test_every_published_figure_is_shown_with_its_papers_citation():
    shorts = {p.short for p in citations.PAPERS.values()}
    for p in published.figures():
        where, what = published.citation(p.source, p.table)
        assert where.split(",")[0] in shorts, (p.source, where)
        assert not LABEL.search(where + what), (where, what)
    assert published.citation("seed 001 (Sztrajman et al., Neural BRDF, CGF 2021)",
                              "Table 2 reconstruction through a 32-d embedding") == (
        "Sztrajman et al. 2021, Table 2", "reconstruction through a 32-d embedding")
    assert published.citation("seed 000 (Hu, Cambridge TR-1005, 2026)", "text 4.3.2.2 efficiency") == (
        "Hu 2026, §4.3.2.2", "efficiency")


def test_the_readme_cites_by_author_and_keeps_one_reference_list():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert _hits(text, "README.md") == []
    assert len(re.findall(r"^## References$", text, re.MULTILINE)) == 1
    references = text.split("\n## References\n", 1)[1]
    assert not re.search(r"^## ", references, re.MULTILINE), "References is the README's last section"
    for p in citations.PAPERS.values():
        assert p.entry in references and p.title in references, p.short
        assert text.count(p.entry) == 1, f"{p.short}: one full entry, in References"
    assert "doi:10.48456/tr-1005" in references


def test_cli_help_and_plugin_list_cite_by_author(capsys):
    hits = _hits(cli._help_text(), "brdfbench --help")
    assert cli.main(["list"]) == 0
    hits += _hits(capsys.readouterr().out, "brdfbench list")
    for group in registry.GROUPS:
        for name in registry.names(group):
            spec = registry.get(group, name)
            for field in dataclasses.fields(spec):
                value = getattr(spec, field.name)
                if isinstance(value, str):
                    hits += _hits(value, f"{group}/{name}.{field.name}")
    assert hits == [], "\n".join(hits)


def _store(path: Path) -> None:
    """A small store: an accuracy section of 10 materials (the sharpest-tenth split and the
    published figures beside ours appear) and a generation section (Table 1's layout)."""
    store = ResultsStore(path / "brdfbench.sqlite")
    common = dict(run_id="r", dataset_fingerprint="fp", status="ok", message="", seed=0, package_version="0.1.0",
                  git_sha="abc", timestamp=1.0)
    store.write_config(ConfigRecord("h_nbrdf", "nbrdf", "nbrdf", "0.1.0", "accuracy", {"representation": "nbrdf"}))
    for i in range(10):
        figures = (("l1_log_cos", 0.01 * (1 + i), "log", False), ("hdr_rmse", 0.65, "1/sr", False),
                   ("model_bytes", 2700.0, "B", False), ("fit_time", 3.0, "s", False),
                   ("evals_per_s", 1e6, "evals/s", True), ("target_lobe_half_width", 0.05 * (1 + i), "rad", False))
        store.write_cell([Row(config_hash="h_nbrdf", dataset="synthetic", material=f"m{i}",
                              category="metal" if i % 2 else "plastic", metric=m, value=v, unit=u,
                              higher_is_better=hib, **common) for m, v, u, hib in figures])
    for h, plugin in (("h_train", "training_set"), ("h_pcan", "pca_nbrdf")):
        store.write_config(ConfigRecord(h, plugin, plugin, "0.1.0", "generation", {"generator": plugin}))
        for draw in range(2):
            rows = [Row(config_hash=h, dataset="neumerl", material=f"draw-{draw}", category=cat, metric=m,
                        value=float(v + draw), unit=unit, higher_is_better=hib, scope="set", distance=d, **common)
                    for m, d, v, unit, hib, cat in (("mmd", "l1", 0.3, "1/sr", False, "set"),
                                                    ("cov", "rmse", 40, "%", True, "set"),
                                                    ("category_count", "", 2, "samples", False, "mirror"))]
            store.write_cell(rows)


def test_the_leaderboards_cite_by_author(tmp_path):
    _store(tmp_path)
    paths = write_reports(tmp_path)
    pages = {p.name: p.read_text(encoding="utf-8") for p in paths if p.suffix in (".md", ".html")}
    assert {"leaderboard.md", "leaderboard.html"} <= set(pages)
    hits = [h for name, text in pages.items() for h in _hits(text, name)]
    assert hits == [], "\n".join(hits)
    md, page = pages["leaderboard.md"], pages["leaderboard.html"]
    assert "Unconditional synthesis (Zhou et al., Table 1)" in md and "Hu 2026, Table 4.5" in md
    assert "the lobe half-width of Zhou et al. (C.3)" in md
    assert "Unconditional synthesis (Zhou et al., Table 1)" in page
    assert "Timonen et al., Table 4" in page and "Sztrajman et al. 2021, Table 3" in page  # published figures
