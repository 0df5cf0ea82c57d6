#!/usr/bin/env bash
# Set up haptic-study on a fresh Debian 12 / Ubuntu machine: the system libraries
# Qt needs (docs: hardware.md §2.3), a virtual environment in .venv and the
# package with its test extra.  Safe to run again: it only installs what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

QT_LIBS="libglib2.0-0 libgl1 libegl1 libxkbcommon0 libfontconfig1 libdbus-1-3"
missing=""
if command -v dpkg-query >/dev/null 2>&1; then
    for pkg in $QT_LIBS python3-venv; do
        dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing="$missing $pkg"
    done
fi
# python3-venv is only needed when the interpreter cannot make a venv by itself.
if python3 -c "import ensurepip, venv" >/dev/null 2>&1; then
    missing=$(echo "$missing" | sed 's/python3-venv//')
fi
missing=$(echo "$missing" | xargs)
if [ -n "$missing" ]; then
    echo "setup: installing system packages: $missing"
    SUDO=""
    [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing
fi

if [ ! -x .venv/bin/python ]; then
    echo "setup: creating .venv"
    python3 -m venv .venv
fi
stamp=.venv/.haptic-study-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    echo "setup: installing haptic-study and its dependencies into .venv"
    .venv/bin/python -m pip install -q --upgrade pip >/dev/null
    .venv/bin/python -m pip install -q -e ".[test]"
    touch "$stamp"
fi
