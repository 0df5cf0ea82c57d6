#!/usr/bin/env bash
# Set up haptic-study on a fresh Debian 12 / Ubuntu machine: the system libraries
# Qt needs (docs: hardware.md §2.3), a virtual environment in .venv and the
# package with its test extra.  Safe to run again: it installs only what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

# Prefer the distribution's interpreter: Debian builds CPython with PGO + LTO,
# which runs the 1 kHz loop's pure-Python hot path ~20 % faster than a plain
# source build (pyenv's default).  Fall back to whatever python3 is on PATH.
PY=python3
if [ -x /usr/bin/python3 ] && /usr/bin/python3 -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
    PY=/usr/bin/python3
fi
if ! "$PY" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
    echo "setup: haptic-study needs Python >= 3.11 ($PY is $("$PY" -V 2>&1))" >&2
    exit 1
fi

QT_LIBS="libglib2.0-0 libgl1 libegl1 libxkbcommon0 libfontconfig1 libdbus-1-3"
# Qt's xcb platform plugin (a real window on an X11 desktop) needs these too since Qt 6.5 (docs/hardware.md §2.3)
QT_LIBS="$QT_LIBS libxkbcommon-x11-0 libxcb-cursor0 libxcb-icccm4 libxcb-image0 libxcb-keysyms1 libxcb-render-util0"
QT_LIBS="$QT_LIBS libxcb-render0 libxcb-shape0 libxcb-xkb1 libxcb-util1"
missing=""
if command -v dpkg-query >/dev/null 2>&1; then
    for pkg in $QT_LIBS; do
        dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing="$missing $pkg"
    done
    # Debian splits venv/ensurepip out of python3
    if ! "$PY" -c "import ensurepip, venv" >/dev/null 2>&1; then
        missing="$missing python3-venv"
    fi
fi
missing=$(echo "$missing" | xargs)
if [ -n "$missing" ]; then
    echo "setup: installing system packages: $missing"
    SUDO=""
    [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing >/dev/null
fi

want="$("$PY" -c 'import sys; print(sys.executable, sys.version.split()[0])')"
stamp=.venv/.haptic-study-python
if [ -d .venv ] && [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    echo "setup: .venv was made by another interpreter; recreating it"
    rm -rf .venv
fi
if [ ! -x .venv/bin/python ]; then
    echo "setup: creating .venv with $want"
    "$PY" -m venv .venv
    echo "$want" > "$stamp"
fi
installed=.venv/.haptic-study-installed
if [ ! -f "$installed" ] || [ pyproject.toml -nt "$installed" ]; then
    echo "setup: installing haptic-study and its dependencies into .venv"
    .venv/bin/python -m pip install -q --upgrade pip >/dev/null
    # pip byte-compiles what it installs on one core (~45 s of the ~70 s here); the libraries are compiled below on
    # every core instead, leaving out their own test suites (a third of their files, never imported by us)
    .venv/bin/python -m pip install -q --no-compile -e ".[test]"
    site=$(.venv/bin/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
    # (a few files of the libraries are not Python 3 -- pip skips them too: the status is not the point here)
    .venv/bin/python -m compileall -q -j 0 -x '/tests?/' "$site" >/dev/null 2>&1 || true
    touch "$installed"
fi
# Byte-compile the product once: every command, study worker and engine process imports it, and where the
# environment forbids writing bytecode at import (PYTHONDONTWRITEBYTECODE) each would compile it again (~0.4 s).
# Quiet, and cheap when nothing changed (only changed files are compiled).
.venv/bin/python -m compileall -q foundation pipeline protocol analysis study_app bench >/dev/null
