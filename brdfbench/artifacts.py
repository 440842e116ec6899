"""Files a cell leaves beside the store (rendered images, lobe slices), indexed by
configuration and material, so a report finds them without knowing a harness's layout.

`<results>/artifacts/<config hash>/<material>.json` maps a kind ("image", "reference",
"lobes", …) to a path relative to the results folder plus what describes it (spp,
sampler). One cell's worker writes its own entry (atomically), so writers never meet.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from .atomic import replacing

FOLDER = "artifacts"


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.@+-]", "_", name)


def index_path(results_dir: Path, config_hash: str, material: str) -> Path:
    return Path(results_dir) / FOLDER / _safe(config_hash) / f"{_safe(material)}.json"


def record(results_dir: Path, config_hash: str, material: str, kind: str, path: Path, **meta: Any) -> None:
    """Add (or replace) one artifact of a cell in its index."""
    index = index_path(results_dir, config_hash, material)
    index.parent.mkdir(parents=True, exist_ok=True)
    entries = lookup(results_dir, config_hash, material)
    try:
        relative = str(Path(path).resolve().relative_to(Path(results_dir).resolve()))
    except ValueError:
        relative = str(Path(path).resolve())
    entries[kind] = {"path": relative, **meta}
    with replacing(index) as tmp:
        tmp.write_text(json.dumps(entries, indent=1, sort_keys=True), encoding="utf-8")


def lookup(results_dir: Path, config_hash: str, material: str) -> dict[str, dict[str, Any]]:
    """A cell's artifacts (kind → entry), {} where it left none or its index is unreadable."""
    try:
        value = json.loads(index_path(results_dir, config_hash, material).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return value if isinstance(value, dict) else {}
