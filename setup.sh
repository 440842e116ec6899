#!/usr/bin/env bash
# Set up brdfbench on a fresh Debian machine: system packages, a virtualenv in .venv,
# and the package (editable) with its test extras. Safe to run again.
set -euo pipefail
cd "$(dirname "$0")"

# Debian packages: LLVM 19 for Mitsuba 3's llvm_* variants (with LLVM 15/16 drjit aborts);
# headless Chromium and its WebDriver for the HTML report's browser test.
if command -v apt-get >/dev/null 2>&1; then
    missing=""
    for pkg in libllvm19 chromium chromium-driver; do
        dpkg -s "$pkg" >/dev/null 2>&1 || missing="$missing $pkg"
    done
    if [ -n "$missing" ]; then
        sudo=""
        [ "$(id -u)" -eq 0 ] || sudo="sudo"
        echo "setup: installing$missing (Debian)"
        $sudo apt-get update -qq
        DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq $missing >/dev/null
    fi
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
