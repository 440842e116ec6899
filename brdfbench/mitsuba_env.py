"""Which Mitsuba 3 variant this process may use, decided before the first kernel runs.

Mitsuba's `llvm_*` variants JIT-compile through the libLLVM that drjit finds at run time.
drjit 1.x needs LLVM ≥ 19: with LLVM 15/16 it aborts the whole process on the first
kernel, which no `try` can catch. So the version is probed once, in a subprocess, and a
process without a usable LLVM falls back to `scalar_rgb` with a warning that says why.
"""

from __future__ import annotations

import contextlib
import functools
import os
import subprocess
import sys
import warnings

from .errors import ConfigError

LLVM_MIN_MAJOR = 19
LLVM_VARIANT = "llvm_ad_rgb"
SCALAR_VARIANT = "scalar_rgb"
VARIANTS = (LLVM_VARIANT, SCALAR_VARIANT)
#: Forces a variant for every Mitsuba use in brdfbench (e.g. scalar_rgb to reproduce a fallback).
VARIANT_ENV = "BRDFBENCH_MITSUBA_VARIANT"


class LLVMFallbackWarning(RuntimeWarning):
    """Mitsuba runs in scalar_rgb (slow, one sample at a time) because no usable LLVM was found."""


@functools.lru_cache(maxsize=1)
def llvm_version() -> tuple[int, ...] | None:
    """The libLLVM version drjit loads, probed in a subprocess (an unsupported one aborts it)."""
    code = (
        "import drjit as dr, mitsuba as mi\n"
        f"mi.set_variant('{LLVM_VARIANT}')\n"
        "x = dr.arange(mi.Float, 8) + 1.0\n"
        "dr.eval(x)\n"
        "print('.'.join(str(v) for v in dr.detail.llvm_version()))\n"
    )
    try:
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=180)
    except (OSError, subprocess.SubprocessError):
        return None
    if out.returncode != 0:
        return None
    try:
        return tuple(int(p) for p in out.stdout.strip().splitlines()[-1].split("."))
    except (ValueError, IndexError):
        return None


def llvm_usable() -> bool:
    version = llvm_version()
    return version is not None and version[0] >= LLVM_MIN_MAJOR


def choose_variant(env: str = VARIANT_ENV, *, warn: bool = True) -> str:
    """`llvm_ad_rgb` where drjit loads LLVM ≥ 19, else `scalar_rgb` (with a warning);
    the environment variable `env` overrides."""
    forced = os.environ.get(env)
    if forced:
        if forced not in VARIANTS:
            raise ConfigError(f"{env}={forced!r} must be one of {', '.join(VARIANTS)}")
        return forced
    if llvm_usable():
        return LLVM_VARIANT
    if warn:
        version = llvm_version()
        found = "no loadable libLLVM" if version is None else "LLVM " + ".".join(map(str, version))
        warnings.warn(
            f"Mitsuba falls back to {SCALAR_VARIANT}: drjit found {found}, and {LLVM_VARIANT} needs "
            f"LLVM >= {LLVM_MIN_MAJOR} (Debian: apt-get install libllvm19). Rendering is much slower.",
            LLVMFallbackWarning, stacklevel=2,
        )
    return SCALAR_VARIANT


@contextlib.contextmanager
def mitsuba_variant(name: str):
    """Set a Mitsuba variant for a block and restore the previous one."""
    if name == LLVM_VARIANT and not llvm_usable():
        raise ConfigError(f"Mitsuba variant {LLVM_VARIANT} needs LLVM >= {LLVM_MIN_MAJOR}; found {llvm_version()}")
    import mitsuba as mi

    previous = mi.variant()
    if previous != name:
        mi.set_variant(name)
    try:
        yield mi
    finally:
        if previous is not None and previous != name:
            mi.set_variant(previous)
