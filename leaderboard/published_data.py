"""The source papers' published figures and which of our metrics each matches, as data.

`data/seed_figures.csv` holds every table of the four source papers as printed (with
their sources); `data/published_matches.csv` says which rows measure what one of our
metrics measures, the unit factor, and the paper's materials and recipe. Its
`representation` names our representation, optionally with the parameters a configuration
must have, `published_fit(source=bagher_sgd)` (`Match.params`). Read here with
no knowledge of reports, so that any part of the report may quote a figure
(`published.compare` sets them beside ours).
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from importlib import resources

from brdfbench import citations

FIGURES_FILE = "seed_figures.csv"
MATCHES_FILE = "published_matches.csv"


@dataclass(frozen=True)
class Published:
    source: str
    table: str
    model: str
    metric: str
    value: float
    std: float | None
    unit: str
    note: str
    printed: str = ""  # the figure as printed, its digits kept ("2.70"): it stands for ±half its last digit

    @property
    def half_step(self) -> float:
        """Half a unit of the last printed digit (0 where the printed text is not known)."""
        try:
            exponent = Decimal(self.printed.strip()).as_tuple().exponent
        except (InvalidOperation, AttributeError):
            return 0.0
        return 0.5 * 10.0 ** exponent if isinstance(exponent, int) else 0.0


@dataclass(frozen=True)
class Match:
    seed: str
    table: str
    model: str
    metric: str
    representation: str
    our_metric: str
    scene: str
    scale: float
    setup: str
    dataset: str = ""  # the paper's materials ("30 MERL/RGL"); "" where the figure does not depend on them
    paper_recipe: str = ""  # how the paper trains the model; "" where it has no training schedule
    recipe_configs: tuple[str, ...] = ()  # our configurations that train on that recipe
    #: parameters our configuration must have, (name, value as text): `published_fit(source=bagher_sgd)`
    params: tuple[tuple[str, str], ...] = ()


def _rows(name: str) -> list[dict[str, str]]:
    text = resources.files("brdfbench_leaderboard").joinpath("data", name).read_text(encoding="utf-8")
    return list(csv.DictReader(text.splitlines()))


#: Where in its paper a figure is printed: "Table 4.1 image quality ..." → ("Table 4.1", "image
#: quality ..."); "section 3.1" and "text 4.3.2.2 efficiency" → "§3.1", "§4.3.2.2".
_WHERE = re.compile(r"(Table|Figure|section|text)\s+(\d+(?:\.\d+)*)\s*(.*)", re.DOTALL)


def citation(source: str, table: str) -> tuple[str, str]:
    """(where, what): a figure's source and table as a report shows them: the paper's citation
    and the place in it ("Sztrajman et al. 2021, Table 2"), and the table's description
    (any internal label in it cited too)."""
    m = _WHERE.fullmatch(table.strip())
    if m is None:
        return citations.source(source), citations.cite(table)
    kind, number, rest = m.groups()
    place = f"§{number}" if kind in ("section", "text") else f"{kind} {number}"
    return f"{citations.source(source)}, {place}", citations.cite(rest)


def _float(text: str | None) -> float | None:
    try:
        value = float(text) if text not in (None, "") else None
    except ValueError:
        return None
    return value if value is None or math.isfinite(value) else None


def figures() -> list[Published]:
    """The numeric published figures (a range printed as text, e.g. "10 to 180", is left out)."""
    out = []
    for r in _rows(FIGURES_FILE):
        value = _float(r.get("value"))
        if value is None:
            continue
        out.append(Published(r["source"], r["table"], r["model"], r["metric"], value, _float(r.get("std")),
                             r.get("unit") or "", r.get("note") or "", (r.get("value") or "").strip()))
    return out


#: `name(key=value, key=value)`: a representation and the parameters a match requires.
_CALL = re.compile(r"\s*([^\s()]+)\s*\((.*)\)\s*", re.DOTALL)


def representation_spec(text: str) -> tuple[str, tuple[tuple[str, str], ...]]:
    """("published_fit", (("source", "bagher_sgd"),)) of "published_fit(source=bagher_sgd)"; a
    plain name has no parameters. ValueError for a malformed parameter list."""
    m = _CALL.fullmatch(text)
    if m is None:
        return text.strip(), ()
    name, inner = m.groups()
    params = []
    for part in filter(None, (p.strip() for p in inner.split(","))):
        key, eq, value = part.partition("=")
        if not eq or not key.strip() or not value.strip():
            raise ValueError(f"{MATCHES_FILE}: representation {text!r}: expected name(key=value, ...)")
        params.append((key.strip(), value.strip()))
    return name, tuple(params)


def matches() -> list[Match]:
    out = []
    for r in _rows(MATCHES_FILE):
        name, params = representation_spec(r["representation"])
        out.append(Match(r["seed"], r["table"], r["model"], r["metric"], name, r["our_metric"], r["scene"],
                         float(r["scale"]), r["setup"], (r.get("dataset") or "").strip(),
                         (r.get("paper_recipe") or "").strip(), tuple((r.get("recipe_configs") or "").split()),
                         params))
    return out
