#!/usr/bin/env bash
# Set up brdfbench on a fresh Debian machine: system packages, a virtualenv in .venv,
# and the package (editable) with its test extras. Safe to run again.
set -euo pipefail
cd "$(dirname "$0")"

# Mitsuba 3's llvm_* variants need LLVM 19 at run time (with LLVM 15/16 drjit aborts).
if command -v apt-get >/dev/null 2>&1 && ! dpkg -s libllvm19 >/dev/null 2>&1; then
    sudo=""
    [ "$(id -u)" -eq 0 ] || sudo="sudo"
    echo "setup: installing libllvm19 (Debian)"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq libllvm19 >/dev/null
fi

PYTHON=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    echo "setup: creating .venv with $($PYTHON --version)"
    "$PYTHON" -m venv .venv
fi
# torch first and pinned: the 2.13.0 CPU build. An unpinned torch would pull a CUDA build.
.venv/bin/python -m pip install -q --disable-pip-version-check torch==2.13.0
.venv/bin/python -m pip install -q --disable-pip-version-check -e ".[test,launchers]"
echo "setup: done ($(.venv/bin/python -c 'import brdfbench, torch; print("brdfbench", brdfbench.__version__, "torch", torch.__version__)'))"
