"""The machines behind a store's figures: which hosts measured them (`hosts`, the report's
header) and how fast each ran a fixed calibration product (`machine_speeds`, the
machine-speed table), so a reader knows which timings may be compared."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from brdfbench.pipeline import calibration


@dataclass(frozen=True)
class Host:
    """A machine (and thread count) that produced figures of the store: what a reader needs
    to know before comparing its timings with their own."""

    host: str
    cpu_model: str
    cores: int  # usable by the process
    threads: int  # torch threads of its tasks
    gpu: str  # the accelerator's description, "" for none
    platform: str  # OS, Python and torch versions ("" in stores older than its recording)
    cells: int  # rows measured there

    @property
    def torch(self) -> str:
        """The torch version, where the platform recorded it."""
        _, found, rest = self.platform.partition(" torch ")
        return rest.split()[0] if found and rest else ""


def hosts(df: pd.DataFrame) -> list[Host]:
    """The machines of a store's rows, most rows first."""
    got = df.copy()
    for col, default in (("host", ""), ("cpu_model", ""), ("cpu_count", 0), ("threads", 0),
                         ("device_detail", "cpu"), ("platform", "")):
        if col not in got.columns:
            got[col] = default
    keys = ["host", "cpu_model", "cpu_count", "threads", "device_detail", "platform"]
    counts = got.groupby(keys, dropna=False).size().reset_index(name="rows")
    out = [Host(str(r.host), str(r.cpu_model), int(r.cpu_count), int(r.threads),
                "" if str(r.device_detail) in ("cpu", "", "nan") else str(r.device_detail), str(r.platform), int(r.rows))
           for r in counts.itertuples()]
    return sorted(out, key=lambda h: (-h.cells, h.host, h.threads))


@dataclass(frozen=True)
class MachineSpeed:
    """The calibration product's speed (GFLOP/s) on one host and thread count: the median
    over its runs (a run: one job's cells) and the slowest and fastest run."""

    host: str
    cpu_model: str
    threads: int
    device: str
    runs: int
    median: float
    low: float
    high: float


#: What the report says of the machine-speed table.
MACHINE_NOTE = (f"A fixed {calibration.SIZE}×{calibration.SIZE} fp32 matrix product, timed on each task's threads "
                "just before it ran (median of its repeats). Where the runs of one host and thread count differ "
                "widely, its cost figures differ for the machine's sake as much as the models': compare timings "
                "of runs whose speeds agree.")


def machine_speeds(df: pd.DataFrame) -> list[MachineSpeed]:
    """The machine-speed table of the store's calibration rows (none in older stores)."""
    rows = df[(df.metric == calibration.METRIC) & (df.status == "ok")]
    if rows.empty:
        return []
    for col, default in (("host", ""), ("cpu_model", ""), ("threads", 0), ("device", "cpu"), ("run_id", "")):
        if col not in rows.columns:
            rows = rows.assign(**{col: default})
    per_run = rows.groupby(["host", "cpu_model", "threads", "device", "run_id"])["value"].median().reset_index()
    out = []
    for (host, cpu, threads, device), g in per_run.groupby(["host", "cpu_model", "threads", "device"]):
        v = g["value"].to_numpy(dtype=float)
        out.append(MachineSpeed(str(host), str(cpu), int(threads), str(device), len(v), float(np.median(v)),
                                float(v.min()), float(v.max())))
    return out
