"""The built-in store backend's spec."""

from __future__ import annotations

from ..plugins.specs import StoreSpec

SQLITE = StoreSpec(
    name="sqlite",
    description="one SQLite file in the results folder (WAL): safe for many processes on one host",
    target="brdfbench.store.sqlite:sqlite_store",
)
