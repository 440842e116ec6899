#!/usr/bin/env bash
# Set up brdfbench on a fresh Debian machine: system packages, a virtualenv in .venv,
# and the package (editable) with its test extras. Safe to run again.
#   bash setup.sh                 the CPU build of torch 2.13.0
#   bash setup.sh --cuda[=cu128]  torch 2.13.0 built for CUDA (that tag) from download.pytorch.org
set -euo pipefail
cd "$(dirname "$0")"

TORCH_INDEX=""
for arg in "$@"; do
    case "$arg" in
        --cuda) TORCH_INDEX="https://download.pytorch.org/whl/cu128" ;;
        --cuda=cu[0-9]*) TORCH_INDEX="https://download.pytorch.org/whl/${arg#--cuda=}" ;;
        *) echo "setup: unknown option '$arg' (known: --cuda, --cuda=cuNNN, e.g. --cuda=cu126)" >&2; exit 2 ;;
    esac
done

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
# With --cuda, the 2.13.0 build for that CUDA version (a GPU is then used with device=auto).
if [ -n "$TORCH_INDEX" ]; then
    echo "setup: installing torch 2.13.0 from $TORCH_INDEX"
    force=""  # a CPU build already here satisfies ==2.13.0: replace it
    .venv/bin/python -c 'import sys, torch; sys.exit(torch.version.cuda is None)' 2>/dev/null || force="--force-reinstall"
    .venv/bin/python -m pip install -q --disable-pip-version-check $force torch==2.13.0 --index-url "$TORCH_INDEX"
else
    .venv/bin/python -m pip install -q --disable-pip-version-check torch==2.13.0
fi
.venv/bin/python -m pip install -q --disable-pip-version-check -e ".[test,launchers,conditioning]"
echo "setup: done ($(.venv/bin/python -c 'import brdfbench, torch; from brdfbench import device; print("brdfbench", brdfbench.__version__, "torch", torch.__version__, "devices:", ", ".join(device.available()))'))"
