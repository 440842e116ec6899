"""Progress of a job: a bar on a terminal for a lone job, plain lines otherwise.

Parallel jobs (joblib, submitit, Ray) write to one terminal or to log files, where bars
overwrite each other: they print one line per finished cell, prefixed with the job.
"""

from __future__ import annotations

import sys
import time

from tqdm.auto import tqdm

from .config import RunConfig


def mode(cfg: RunConfig) -> str:
    if cfg.progress != "auto":
        return cfg.progress
    return "bar" if cfg.launcher == "basic" and sys.stderr.isatty() else "lines"


class Progress:
    def __init__(self, cfg: RunConfig, total: int, skipped: int, unit: str = "material"):
        self.mode = mode(cfg)
        self.cfg = cfg
        self.total = total
        self.count = skipped
        self.start = time.monotonic()
        self.prefix = f"[job {cfg.job}] " if cfg.job else ""
        self.bar = None
        what = f"{cfg.label} on {cfg.dataset}"
        if self.mode == "bar":
            self.bar = tqdm(total=total, initial=skipped, desc=what, unit=unit, dynamic_ncols=True)
        elif self.mode == "lines":
            self._line(f"{what}: {total} {unit}s, {skipped} already in the store")

    def _line(self, text: str) -> None:
        print(f"{self.prefix}{text}", file=sys.stderr, flush=True)

    def note(self, text: str) -> None:
        """Long work starting (training, a batch fit): a line in `lines` mode, so a log shows
        what the job is doing between cells; a bar shows it through the fit's own bar."""
        if self.mode == "lines":
            self._line(f"{text} ({time.monotonic() - self.start:.0f} s)")

    def cell(self, material: str, status: str, measurements: list) -> None:
        self.count += 1
        fit = next((m.value for m in measurements if m.metric == "fit_time"), None)
        if self.bar is not None:
            self.bar.update(1)
            if fit is not None:
                self.bar.set_postfix(fit_s=f"{fit:.2f}")
        elif self.mode == "lines":
            detail = f"fit {fit:.2f} s" if fit is not None else status
            self._line(f"{self.cfg.label} {self.count}/{self.total} {material}: {detail} "
                       f"({time.monotonic() - self.start:.0f} s)")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
