"""The four source papers brdfbench was built from, and how the product cites them.

Source: the project's reference notes on the four papers, which give each paper's full
entry and the rule: wherever a user reads (README, CLI help, plugin
descriptions, docstrings, reports and leaderboards) a paper is cited by its authors and
title, with the year where the paper gives it, and the README keeps the one reference list
with the full entries (its "References" section, the same text as `Paper.entry` here).

The published-figures data (`brdfbench_leaderboard/data/seed_figures.csv` and
`published_matches.csv`, copies of the project's reference tables) key each row by an
internal label of its paper. Those labels stay the data's keys; `source` and `cite` turn
them into the citation wherever a report displays them.

Two of the papers do not print their year, so their short citation has none:
Timonen et al. and Zhou et al.
"""

from __future__ import annotations

import re
from dataclasses import dataclass


@dataclass(frozen=True)
class Paper:
    label: str  # the data's key (the `seed` / `source` columns of the published-figures tables)
    short: str  # the in-text citation, e.g. "Sztrajman et al. 2021"
    title: str
    entry: str  # the full reference, as in the README's References section


PAPERS: dict[str, Paper] = {p.label: p for p in (
    Paper("seed 000", "Hu 2026", "Neural representation of Bidirectional Reflectance Distribution Function",
          "Zheyuan Hu. Neural representation of Bidirectional Reflectance Distribution Function. Technical "
          "Report UCAM-CL-TR-1005, University of Cambridge Computer Laboratory, 2026. doi:10.48456/tr-1005"),
    Paper("seed 001", "Sztrajman et al. 2021", "Neural BRDF Representation and Importance Sampling",
          "Alejandro Sztrajman, Gilles Rainer, Tobias Ritschel, Tim Weyrich. Neural BRDF Representation and "
          "Importance Sampling. Computer Graphics Forum, 2021."),
    Paper("seed 002", "Timonen et al.", "A Real-Time Multi-Scale Neural Representation for Complex Surface "
          "Reflectance",
          "Heikki Timonen, Pauli Kemppinen, Jaakko Lehtinen. A Real-Time Multi-Scale Neural Representation for "
          "Complex Surface Reflectance."),
    Paper("seed 003", "Zhou et al.", "NeuMaDiff: Neural Material Synthesis via Hyperdiffusion",
          "Chenliang Zhou, Zheyuan Hu, Alejandro Sztrajman, Yancheng Cai, Yaru Liu, Cengiz Oztireli. NeuMaDiff: "
          "Neural Material Synthesis via Hyperdiffusion."),
)}

#: An internal label in any of its spellings: the word, then a space, hyphen, underscore or
#: nothing, then the paper's three-digit number (any case).
LABEL = re.compile(r"\bseed[ _-]?(00[0-3])\b", re.IGNORECASE)


def paper(label: str) -> Paper:
    """The paper of an internal label, in any spelling `LABEL` matches."""
    m = LABEL.fullmatch(label.strip())
    if m is None:
        raise KeyError(f"not a source paper's label: {label!r} (known: {', '.join(PAPERS)})")
    return PAPERS[f"seed {m.group(1)}"]


def source(text: str) -> str:
    """A published figure's source as a report shows it: the short citation of the paper
    whose label the text starts with (the `source` column of `seed_figures.csv`: a label,
    then a parenthesis, → e.g. "Sztrajman et al. 2021"); text that starts with no label is
    returned with any label in it cited (`cite`)."""
    m = LABEL.match(text.strip())
    return PAPERS[f"seed {m.group(1)}"].short if m else cite(text)


def cite(text: str) -> str:
    """`text` with every internal label replaced by the short citation of its paper."""
    return LABEL.sub(lambda m: PAPERS[f"seed {m.group(1)}"].short, text)


def references_markdown() -> str:
    """The full entries as a Markdown list, in the README's order."""
    return "\n".join(f"- {p.short}: {p.entry}" for p in PAPERS.values())
