"""Where a figure was measured, so cost figures can be compared honestly.

The environment (host, CPU model, usable cores, torch threads, launcher, platform, and the
device that computed the figures) is stored once per distinct value. Concurrency is counted per cell: every worker holds a
marker file named by its pid in a host-wide folder while it runs a task, and a cell
records how many live markers there were (itself included), whichever launcher or shell
started the other jobs.
"""

from __future__ import annotations

import os
import platform
import socket
import tempfile
from functools import lru_cache
from importlib import metadata
from pathlib import Path

from ..provenance import config_hash
from ..store.protocol import Environment

ACTIVE_DIR = Path(tempfile.gettempdir()) / f"brdfbench-active-{os.getuid() if hasattr(os, 'getuid') else 0}"


@lru_cache(maxsize=1)
def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def usable_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def platform_text() -> str:
    """OS, architecture, Python and torch versions: what a report says produced its figures."""
    try:
        torch_version = metadata.version("torch")
    except metadata.PackageNotFoundError:
        torch_version = "absent"
    return f"{platform.system()} {platform.machine()} Python {platform.python_version()} torch {torch_version}"


def environment(threads: int, launcher: str, device: tuple[str, str] = ("cpu", "cpu")) -> Environment:
    """This host's environment; `device` is (name, description) of where the figures were
    computed (`brdfbench.device.name` and `describe`)."""
    fields = {"host": socket.gethostname(), "cpu_model": cpu_model(), "cpu_count": usable_cores(), "threads": int(threads),
              "launcher": launcher, "platform": platform_text()}
    if device[0] != "cpu":  # a CPU environment keeps the id it had before devices were recorded
        fields.update(device=device[0], device_detail=device[1])
    return Environment(env_id=config_hash(fields), **fields)


class ActiveMarker:
    """This process's marker while it runs a task; `count()` of live brdfbench workers on the host."""

    def __init__(self, folder: Path = ACTIVE_DIR):
        self.folder = folder
        self.path = folder / str(os.getpid())

    def __enter__(self) -> "ActiveMarker":
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            self.path.touch()
        except OSError:
            pass
        return self

    def __exit__(self, *exc) -> None:
        self.path.unlink(missing_ok=True)

    def count(self) -> int:
        live = 0
        try:
            entries = list(self.folder.iterdir())
        except OSError:
            return 1
        for entry in entries:
            if not entry.name.isdigit():
                continue
            if _alive(int(entry.name)):
                live += 1
            else:  # a worker that was killed left its marker behind
                entry.unlink(missing_ok=True)
        return max(live, 1)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
