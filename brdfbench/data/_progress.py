"""Progress of long dataset work (a PCA build, NBRDF fits): a bar on a terminal, lines otherwise.

A log file or a parallel launcher gets plain lines on stderr (`<label>: 48/228 <what>
(3.1 per minute)`), at most one per `LINE_EVERY_S` seconds plus the last; a terminal gets a
tqdm bar. The CLI logs at WARNING, so these are printed, not logged.
"""

from __future__ import annotations

import sys
import time

from tqdm.auto import tqdm

#: Least seconds between two progress lines (the last one is always printed).
LINE_EVERY_S = 10.0


def note(text: str) -> None:
    """One line on stderr (a start, a summary)."""
    print(text, file=sys.stderr, flush=True)


class Progress:
    """Counts finished items of `total`; `bar=None` picks a bar when stderr is a terminal."""

    def __init__(self, label: str, total: int, what: str, *, bar: bool | None = None, initial: int = 0):
        self.label, self.total, self.what = label, total, what
        self.count = initial
        self.start = time.monotonic()
        self.last_line = -float("inf")
        self.done_here = 0
        use_bar = sys.stderr.isatty() if bar is None else bar
        self.bar = tqdm(total=total, initial=initial, desc=label, unit=what.rstrip("s"), dynamic_ncols=True,
                        leave=False) if use_bar else None

    def rate_per_minute(self) -> float:
        elapsed = time.monotonic() - self.start
        return 60.0 * self.done_here / elapsed if elapsed > 0 else 0.0

    def update(self, n: int = 1) -> None:
        self.count += n
        self.done_here += n
        if self.bar is not None:
            self.bar.update(n)
            return
        now = time.monotonic()
        if self.count >= self.total or now - self.last_line >= LINE_EVERY_S:
            self.last_line = now
            note(f"{self.label}: {self.count}/{self.total} {self.what} ({self.rate_per_minute():.1f} per minute)")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
