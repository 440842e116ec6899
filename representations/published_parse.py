"""Reading published analytic fits of MERL materials: BBM's `.fit` files, parsed, never executed.

A file holds `#` comment lines (the first ones cite the paper) and one line per material,
`name = Aggregate(Lambertian(albedo = [r, g, b]), Model(param = value, ...))`, values being
numbers or (nested) lists of numbers. A small tokenizer and recursive-descent parser read
the right-hand side into calls, lists and floats; nothing is evaluated as code.

A line that does not parse, names no material, repeats one, or holds a non-finite number
becomes a failure of that material (or of that line, where no name can be read), with the
file and line in its message; the rest of the file loads. Whether a model name is known,
and whether its parameters lie in its domain, is for the representation that uses the fit.
"""

from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from brdfbench.errors import DataError

_TOKEN = re.compile(
    r"\s*(?:(?P<number>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:inf|nan)\b)"
    r"|(?P<name>[A-Za-z_][A-Za-z0-9_]*)|(?P<punct>[()\[\],=]))"
)


class ParseError(ValueError):
    """A malformed right-hand side; the message says what was expected and at which column."""


@dataclass(frozen=True)
class Call:
    """`Name(args..., key = value, ...)` as written."""

    name: str
    args: tuple[Any, ...]
    kwargs: dict[str, Any]


def _tokens(text: str) -> list[tuple[str, str, int]]:
    out, pos = [], 0
    while pos < len(text):
        if text[pos:].strip() == "":
            break
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            raise ParseError(f"unexpected character {text[pos:].lstrip()[:1]!r} at column {pos + 1}")
        kind = m.lastgroup
        out.append((kind, m.group(kind), m.start(kind) + 1))
        pos = m.end()
    return out


class _Parser:
    def __init__(self, text: str):
        self.toks = _tokens(text)
        self.i = 0

    def peek(self) -> tuple[str, str, int] | None:
        return self.toks[self.i] if self.i < len(self.toks) else None

    def take(self, value: str | None = None, kind: str | None = None) -> tuple[str, str, int]:
        tok = self.peek()
        if tok is None:
            raise ParseError(f"line ends where {value or kind} was expected")
        if (value is not None and tok[1] != value) or (kind is not None and tok[0] != kind):
            raise ParseError(f"expected {value or kind} at column {tok[2]}, found {tok[1]!r}")
        self.i += 1
        return tok

    def value(self) -> Any:
        tok = self.peek()
        if tok is None:
            raise ParseError("line ends where a value was expected")
        kind, text, col = tok
        if kind == "number":
            self.i += 1
            return float(text)
        if text == "[":
            self.i += 1
            items = [self.value()]
            while self.peek() is not None and self.peek()[1] == ",":
                self.i += 1
                items.append(self.value())
            self.take("]")
            return items
        if kind == "name":
            self.i += 1
            return self.call(text)
        raise ParseError(f"expected a number, a list or a model at column {col}, found {text!r}")

    def call(self, name: str) -> Call:
        self.take("(")
        args, kwargs = [], {}
        if self.peek() is not None and self.peek()[1] == ")":
            self.i += 1
            return Call(name, (), {})
        while True:
            tok = self.peek()
            nxt = self.toks[self.i + 1] if self.i + 1 < len(self.toks) else None
            if tok is not None and tok[0] == "name" and nxt is not None and nxt[1] == "=":
                self.i += 2
                if tok[1] in kwargs:
                    raise ParseError(f"{name}: parameter {tok[1]!r} given twice (column {tok[2]})")
                kwargs[tok[1]] = self.value()
            else:
                if kwargs:
                    raise ParseError(f"{name}: positional argument after keyword ones at column {tok[2] if tok else '?'}")
                args.append(self.value())
            sep = self.take(kind="punct")
            if sep[1] == ")":
                return Call(name, tuple(args), kwargs)
            if sep[1] != ",":
                raise ParseError(f"expected ',' or ')' at column {sep[2]}, found {sep[1]!r}")


def parse_expression(text: str) -> Any:
    """The value written in `text` (a call, list or number); ParseError if malformed."""
    p = _Parser(text)
    out = p.value()
    if p.peek() is not None:
        raise ParseError(f"unexpected {p.peek()[1]!r} at column {p.peek()[2]} after the expression")
    return out


def _all_finite(value: Any) -> bool:
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, list):
        return all(_all_finite(v) for v in value)
    if isinstance(value, Call):
        return all(_all_finite(v) for v in (*value.args, *value.kwargs.values()))
    return True


@dataclass(frozen=True)
class PublishedFit:
    """One material's published fit: the Lambertian albedo and the specular model's parameters."""

    material: str
    model: str
    diffuse: tuple[float, float, float]
    params: dict[str, Any]
    line: int


def fit_from_expression(material: str, expr: Any, line: int) -> PublishedFit:
    """Read `Aggregate(Lambertian(albedo=...), Model(...))` (or a bare `Model(...)`, no diffuse)."""
    if not isinstance(expr, Call):
        raise ParseError("expected a model, e.g. Aggregate(Lambertian(...), Model(...))")
    if not _all_finite(expr):
        raise ParseError("a parameter is not a finite number")
    diffuse: tuple[float, float, float] = (0.0, 0.0, 0.0)
    parts = [expr]
    if expr.name == "Aggregate":
        if expr.kwargs or len(expr.args) != 2:
            raise ParseError(f"Aggregate of {len(expr.args) + len(expr.kwargs)} parts: expected Lambertian(...) and one model")
        parts = list(expr.args)
        lam = next((p for p in parts if isinstance(p, Call) and p.name == "Lambertian"), None)
        if lam is None:
            raise ParseError("Aggregate without a Lambertian(albedo = [r, g, b]) part")
        parts.remove(lam)
        albedo = lam.kwargs.get("albedo")
        if set(lam.kwargs) != {"albedo"} or lam.args or not (
            isinstance(albedo, list) and len(albedo) == 3 and all(isinstance(v, float) for v in albedo)
        ):
            raise ParseError("Lambertian needs exactly albedo = [r, g, b]")
        diffuse = (albedo[0], albedo[1], albedo[2])
    model = parts[0]
    if not isinstance(model, Call) or model.args:
        raise ParseError("the specular model must be written Model(param = value, ...)")
    return PublishedFit(material, model.name, diffuse, dict(model.kwargs), line)


@dataclass
class FitFile:
    """A parsed `.fit` file: the fits by material, and what failed, by material or line."""

    source: str
    path: Path
    citation: str
    fits: dict[str, PublishedFit] = field(default_factory=dict)
    failures: dict[str, str] = field(default_factory=dict)  # material -> message
    bad_lines: list[str] = field(default_factory=list)  # lines without a readable material name

    @property
    def materials(self) -> list[str]:
        return sorted({*self.fits, *self.failures})

    def lookup(self, material: str) -> PublishedFit:
        """The fit of `material`; DataError naming the source (and the closest name) otherwise."""
        if material in self.fits:
            return self.fits[material]
        if material in self.failures:
            raise DataError(self.failures[material])
        close = difflib.get_close_matches(material, self.materials, n=1, cutoff=0.6)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise DataError(f"{self.path}: no published fit of {material!r} in {self.source} "
                        f"({len(self.materials)} materials){hint}")


def parse_fit_text(text: str, *, source: str, path: Path) -> FitFile:
    """Parse the text of a `.fit` file; a broken line fails only its material."""
    comments = []
    out = FitFile(source, path, "")
    seen: dict[str, int] = {}
    for n, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            if not seen:
                comments.append(line.lstrip("#").strip())
            continue
        name, eq, rhs = line.partition("=")
        name = name.strip()
        where = f"{path}:{n}"
        if not eq or not name or not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.+-]*", name):
            out.bad_lines.append(f"{where}: expected 'material = Model(...)', got {line[:60]!r}")
            continue
        if name in seen:
            out.fits.pop(name, None)
            out.failures[name] = f"{where}: material {name!r} is given twice (lines {seen[name]} and {n})"
            continue
        seen[name] = n
        try:
            out.fits[name] = fit_from_expression(name, parse_expression(rhs), n)
        except ParseError as exc:
            out.failures[name] = f"{where}: {name}: {exc}"
    out.citation = next((c for c in comments if c.startswith('"') or "[" in c), comments[0] if comments else "")
    return out


def read_fit_file(path: Path, source: str | None = None) -> FitFile:
    """Parse the `.fit` file at `path` (UTF-8); DataError naming it if it cannot be read."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: cannot read published fits ({getattr(exc, 'strerror', None) or exc})") from None
    parsed = parse_fit_text(text, source=source or Path(path).stem.lower(), path=Path(path))
    if not parsed.fits and not parsed.failures:
        raise DataError(f"{path}: no 'material = Model(...)' line; not a published-fit file")
    return parsed
