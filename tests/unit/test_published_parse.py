"""The published-fit parser: every shipped file reads whole; a broken line fails only its
material, with the file and line named; nothing in a file is ever executed."""

from __future__ import annotations

from pathlib import Path

import pytest

from brdfbench.errors import DataError
from brdfbench_representations.published_parse import (Call, ParseError, parse_expression, parse_fit_text,
                                                       read_fit_file)

SHIPPED = Path(__file__).resolve().parents[2] / "representations" / "published_fits"
#: Materials per file: Ngan et al. published 86 of the 100 MERL materials (BBM's collection).
COUNTS = {"ngan": 86, "low": 100, "bagher": 100}
GOOD = "alum-bronze = Aggregate(Lambertian(albedo = [0.1, 0.2, 0.3]), NganWard(albedo = [0.01, 0.02, 0.03], roughness = 0.05))"


def test_every_shipped_file_parses_whole():
    files = sorted(SHIPPED.glob("*.fit"))
    assert len(files) == 14
    for path in files:
        parsed = read_fit_file(path)
        assert not parsed.failures and not parsed.bad_lines, (path, parsed.failures, parsed.bad_lines)
        assert len(parsed.fits) == COUNTS[path.stem.split("_")[0]], path
        assert len({f.model for f in parsed.fits.values()}) == 1
        assert parsed.citation.startswith('"') and "[" in parsed.citation  # the paper, from the header
        for fit in parsed.fits.values():
            assert len(fit.diffuse) == 3 and all(v >= 0 for v in fit.diffuse)


def test_values_are_read_as_written():
    fits = read_fit_file(SHIPPED / "bagher_sgd.fit")
    fit = fits.lookup("alum-bronze")
    assert fit.model == "Bagher" and fit.line == 3
    assert fit.diffuse == (0.0478786, 0.0313514, 0.0200638)
    assert fit.params["alpha"] == [0.014832, 0.0300126, 0.0490339]
    assert fit.params["eta"] == [[6.05524, 0.235756, 0.580647], [5.05524, 0.182842, 0.476088]]
    assert parse_expression("[1e-3, -2.5E+2, .5, 7]") == [1e-3, -250.0, 0.5, 7.0]
    assert parse_expression("M()") == Call("M", (), {})


@pytest.mark.parametrize("rhs, words", [
    ("Aggregate(Lambertian(albedo = [0.1, 0.2, 0.3]), NganWard(albedo = [0.01, 0.02, 0.03], roughness = 0.05)",
     "line ends"),
    ("Aggregate(Lambertian(albedo = [0.1, 0.2]), NganWard(roughness = 0.05))", "albedo = [r, g, b]"),
    ("Aggregate(Lambertian(albedo = [0.1, 0.2, 0.3]), NganWard(roughness = nan))", "not a finite number"),
    ("Aggregate(Lambertian(albedo = [0.1, 0.2, 0.3]), NganWard(roughness = 0.1, roughness = 0.2))", "given twice"),
    ("Aggregate(Lambertian(albedo = [0.1, 0.2, 0.3]), NganWard(roughness = 0.1)) extra", "after the expression"),
    ("Aggregate(NganWard(roughness = 0.1), NganWard(roughness = 0.2))", "without a Lambertian"),
    ("Aggregate(Lambertian(albedo = [0.1, 0.2, 0.3]), A(x = 1), B(y = 2))", "Aggregate of 3 parts"),
    ("__import__('os').system('touch /tmp/brdfbench-pwned')", "unexpected character"),
    ("0.5", "expected a model"),
])
def test_a_malformed_line_fails_only_its_material(rhs, words, tmp_path):
    text = f"# header\n{GOOD}\nbroken-one = {rhs}\n"
    parsed = parse_fit_text(text, source="mine", path=tmp_path / "mine.fit")
    assert list(parsed.fits) == ["alum-bronze"]
    assert set(parsed.failures) == {"broken-one"}
    message = parsed.failures["broken-one"]
    assert message.startswith(f"{tmp_path / 'mine.fit'}:3: broken-one: ") and words in message, message
    with pytest.raises(DataError, match="mine.fit:3"):
        parsed.lookup("broken-one")
    assert not Path("/tmp/brdfbench-pwned").exists()


def test_lines_without_a_name_and_repeated_names(tmp_path):
    text = f"{GOOD}\n= NganWard(roughness = 0.1)\njust words\n{GOOD}\n"
    parsed = parse_fit_text(text, source="mine", path=tmp_path / "mine.fit")
    assert not parsed.fits
    assert "given twice (lines 1 and 4)" in parsed.failures["alum-bronze"]
    assert [b.split(": ", 1)[0] for b in parsed.bad_lines] == [f"{tmp_path / 'mine.fit'}:2", f"{tmp_path / 'mine.fit'}:3"]


def test_an_unknown_material_gets_did_you_mean(tmp_path):
    parsed = read_fit_file(SHIPPED / "ngan_ward.fit")
    with pytest.raises(DataError, match=r"no published fit of 'blue-acrylc' in ngan_ward \(86 materials\); did you mean 'blue-acrylic'\?"):
        parsed.lookup("blue-acrylc")
    with pytest.raises(DataError, match=r"no published fit of 'synth-plastic-green-00' in ngan_ward \(86 materials\)$"):
        parsed.lookup("synth-plastic-green-00")


def test_unreadable_or_empty_files_are_one_line(tmp_path):
    with pytest.raises(DataError, match="missing.fit: cannot read published fits"):
        read_fit_file(tmp_path / "missing.fit")
    (tmp_path / "empty.fit").write_text("# only a comment\n")
    with pytest.raises(DataError, match="empty.fit: no 'material = Model"):
        read_fit_file(tmp_path / "empty.fit")
    (tmp_path / "binary.fit").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(DataError, match="binary.fit: cannot read published fits"):
        read_fit_file(tmp_path / "binary.fit")


def test_parse_errors_say_where():
    with pytest.raises(ParseError, match=r"expected \( at column 5, found '1'"):
        parse_expression("M(x 1)")
