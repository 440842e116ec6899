"""published_fit through the CLI: a material without a usable published fit is a named
failure row and a non-zero exit, never a stopped job; the other cells are measured."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

SMALL = ["dataset.params.size=small", "harness=quick", "progress=lines", "limit=2"]
NBRDF_DIR = Path(__file__).resolve().parents[3] / "shared" / "data" / "neural-brdf"


def _statuses(res: Path) -> list[tuple[str, str]]:
    with sqlite3.connect(res / "brdfbench.sqlite") as db:
        return sorted(db.execute("select material, status from results"))


def test_synthetic_materials_have_no_published_fit_each_a_named_failure(tmp_path, cli):
    res = tmp_path / "res"
    out = cli("representation=published_fit", *SMALL, f"results_dir={res}", cwd=tmp_path)
    assert out.returncode == 1, out.stdout + out.stderr
    rows = _statuses(res)
    assert len(rows) == 2 and all(status == "failed" for _, status in rows)
    assert "no published fit of 'synth-" in out.stdout + out.stderr
    assert "Traceback" not in out.stdout + out.stderr


def test_a_bad_source_is_one_line_before_any_work(tmp_path, cli):
    res = tmp_path / "res"
    out = cli("representation=published_fit", "representation.params.source=ngan_wrd", *SMALL, f"results_dir={res}",
              cwd=tmp_path)
    assert out.returncode == 2
    assert "unknown source 'ngan_wrd'; did you mean 'ngan_ward'?" in out.stderr
    assert not (res / "brdfbench.sqlite").exists()


@pytest.mark.skipif(not NBRDF_DIR.is_dir(), reason="the published NBRDF networks (../shared/data/neural-brdf) are absent")
def test_published_fits_of_the_merl_networks_and_a_model_without_implementation(tmp_path, cli):
    mine = tmp_path / "mine.fit"  # a user's file of fits of a model brdfbench does not implement
    mine.write_text("".join(f"{m} = Aggregate(Lambertian(albedo = [0.1, 0.1, 0.1]), Mystery(albedo = [0.05, 0.05, 0.05]))\n"
                            for m in ("alum-bronze", "alumina-oxide")), encoding="utf-8")
    res = tmp_path / "res"
    out = cli("-m", "representation=published_fit", f"representation.params.source=ngan_ward,ngan_he,{mine}",
              "dataset=nbrdf_release", f"dataset.params.path={NBRDF_DIR}", "harness=quick", "progress=lines", "limit=2",
              f"results_dir={res}", cwd=tmp_path)
    assert out.returncode == 1, out.stdout + out.stderr  # mine.fit's cells failed; the sweep went on
    with sqlite3.connect(res / "brdfbench.sqlite") as db:
        statuses = sorted({s for (s,) in db.execute("select status from results")})
        messages = [m for (m,) in db.execute("select message from results where status = 'failed'")]
        ok = db.execute("select count(*) from (select distinct config_hash, material from results where status = 'ok')").fetchone()
    assert statuses == ["failed", "ok"] and ok == (4,)  # ngan_ward's and ngan_he's (He et al. 1991) cells
    assert len(messages) == 2 and all("no brdfbench model evaluates 'Mystery' fits" in m and "mine.fit:" in m for m in messages)
    assert (res / "leaderboard.md").exists()
