"""Constrained synthesis (Zhou et al. § 4.5, Hu 2026 § 3.6): samples of one material category, by rejection.

A fitted generator draws batches; each finite sample is built and classified by the
statistics-based rules of `brdfbench.data.categories`; samples in the asked category are
kept until there are `n` or `max_draws` have been drawn. What it costs is part of the
answer: the acceptance rate, and the time per accepted sample (drawing, building and
classifying all of them, rejected ones included).

Batch k is drawn with a seed derived from (`seed`, k), so a run is reproducible and
batches do not repeat each other's draws.
"""

from __future__ import annotations

import difflib
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .data.categories import CATEGORIES, PUBLISHED, Thresholds, categories
from .errors import ConfigError


@dataclass
class ConstrainedDraw:
    """The outcome of one constrained synthesis."""

    category: str
    asked: int
    samples: list = field(default_factory=list)  # the accepted samples, built (fitted representations)
    representation: str = ""  # the registered representation they are instances of
    drawn: int = 0  # samples drawn and examined, accepted or not
    non_finite: int = 0  # drawn samples with a non-finite parameter (never built)
    seconds: float = 0.0

    @property
    def accepted(self) -> int:
        return len(self.samples)

    @property
    def acceptance_rate(self) -> float:
        return self.accepted / self.drawn if self.drawn else 0.0

    @property
    def seconds_per_accepted(self) -> float:
        return self.seconds / self.accepted if self.accepted else float("inf")

    @property
    def complete(self) -> bool:
        return self.accepted >= self.asked


def checked_category(category: str) -> str:
    """`category` if it is one of the seven, else a ConfigError with the nearest."""
    if category in CATEGORIES:
        return category
    near = difflib.get_close_matches(str(category), CATEGORIES, n=2)
    hint = f"; did you mean {' or '.join(repr(c) for c in near)}?" if near else ""
    raise ConfigError(f"category={category!r} is not a material category{hint} (one of {', '.join(CATEGORIES)})")


def _count(key: str, value, low: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise ConfigError(f"{key}={value!r} must be an integer ≥ {low}")
    return int(value)


def batch_seed(seed: int, k: int) -> int:
    """The seed of batch k of a run seeded `seed`."""
    return int(np.random.SeedSequence([seed, k]).generate_state(1)[0] & 0x7FFFFFFF)


def constrained_samples(generator, category: str, n: int, *, seed: int = 0, batch: int = 32, max_draws: int = 4096,
                        thresholds: Thresholds = PUBLISHED,
                        on_batch: Callable[[ConstrainedDraw], None] | None = None) -> ConstrainedDraw:
    """Up to `n` samples of `generator` in `category`, drawn `batch` at a time, at most
    `max_draws` in all; `on_batch(draw so far)` after each batch (progress)."""
    category = checked_category(category)
    n, batch, max_draws = _count("n", n), _count("batch", batch), _count("max_draws", max_draws)
    seed = _count("seed", seed, low=0)
    if max_draws < n:
        raise ConfigError(f"max_draws={max_draws} is below n={n}: at most max_draws samples are drawn")
    out = ConstrainedDraw(category, n)
    start = time.perf_counter()
    k = 0
    while not out.complete and out.drawn < max_draws:
        size = min(batch, max_draws - out.drawn)
        drawn = generator.sample(size, seed=batch_seed(seed, k))
        out.representation = drawn.representation
        finite = drawn.finite.tolist()
        for i in range(len(drawn)):
            out.drawn += 1
            if not finite[i]:
                out.non_finite += 1
                continue
            sample = drawn[i]
            if category in categories(sample, thresholds):
                out.samples.append(sample)
                if out.complete:
                    break
        out.seconds = time.perf_counter() - start
        k += 1
        if on_batch is not None:
            on_batch(out)
    return out
