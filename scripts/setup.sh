#!/usr/bin/env bash
# Idempotent installer for sofac on Debian/Ubuntu, used by scripts/demo.sh and scripts/test.sh:
#
#   1. the Debian packages the build stage needs (Eigen, SuiteSparse, OSMesa, g++) and those the
#      viewer's tests need (Xvfb, xdotool, Mesa), via apt-get;
#   2. sofac itself, editable, with its test extras: python -m pip install -e ".[test]".
#      Where the system Python is "externally managed" (PEP 668), into a .venv in the checkout.
#
# Each step is skipped when already done. Works unattended (CI=true, no standard input).
# PYTHON selects the interpreter (default: .venv/bin/python if present, else python3).
set -euo pipefail
cd "$(dirname "$0")/.."
# shellcheck source=scripts/python.sh
source scripts/python.sh

DEB_PACKAGES=(libeigen3-dev libsuitesparse-dev libosmesa6-dev g++)
# tests/test_view.py runs `sofac view` for real: a virtual X server with Mesa's software OpenGL,
# xdotool to send it keys and mouse events, and the X libraries the glfw wheel's GLFW loads.
DEB_PACKAGES+=(xvfb xdotool libgl1-mesa-dri libxrandr2 libxinerama1 libxcursor1 libxi6)

log() { printf 'setup: %s\n' "$*"; }

deb_missing() {  # prints the packages of "$@" that are not installed
    local pkg
    for pkg in "$@"; do
        dpkg -s "$pkg" 2>/dev/null | grep -q '^Status: install ok installed' || printf '%s\n' "$pkg"
    done
}

ensure_deb_packages() {  # installs the missing ones among "$@", as root or with sudo
    local -a missing sudo_cmd
    if ! command -v dpkg >/dev/null 2>&1; then
        log "no dpkg here (not Debian/Ubuntu): make sure these are installed: $*" >&2
        return 0
    fi
    mapfile -t missing < <(deb_missing "$@")
    if ((${#missing[@]} == 0)); then
        log "Debian packages present: $*"
        return 0
    fi
    if [[ "$(id -u)" == 0 ]]; then
        sudo_cmd=()
    elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
        sudo_cmd=(sudo -n)
    else
        printf 'setup: missing Debian packages: %s\n' "${missing[*]}" >&2
        printf 'setup: installing them needs root; run:\n  sudo sh -c "%s"\nthen run this script again.\n' \
            "apt-get update && apt-get install -y --no-install-recommends ${missing[*]}" >&2
        exit 1
    fi
    log "installing Debian packages: ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    "${sudo_cmd[@]}" apt-get update -q </dev/null
    "${sudo_cmd[@]}" apt-get install -y -q --no-install-recommends "${missing[@]}" </dev/null
}

# --- 1. Debian packages ----------------------------------------------------------------------
command -v "$PYTHON" >/dev/null 2>&1 || ensure_deb_packages python3
ensure_deb_packages "${DEB_PACKAGES[@]}"

# --- 2. a Python that pip may install into ---------------------------------------------------
externally_managed() {
    "$PYTHON" - <<'PY'
import os, sys, sysconfig
in_venv = sys.prefix != sys.base_prefix
marker = os.path.join(sysconfig.get_path("stdlib"), "EXTERNALLY-MANAGED")
sys.exit(0 if not in_venv and os.path.exists(marker) else 1)
PY
}
if externally_managed; then
    log "$PYTHON is managed by the system (PEP 668): using a virtual environment in .venv"
    "$PYTHON" -c 'import ensurepip, venv' 2>/dev/null || ensure_deb_packages python3-venv
    "$PYTHON" -m venv .venv
    PYTHON="$PWD/.venv/bin/python"
fi
if ! "$PYTHON" -m pip --version >/dev/null 2>&1; then
    ensure_deb_packages python3-pip
fi

# --- 3. sofac, editable, with the test extras ------------------------------------------------
# Done when sofac imports from this checkout at pyproject's version and every requirement named in
# pyproject.toml (dependencies and the test extra) is installed.
installed_ok() {
    "$PYTHON" - <<'PY' 2>/dev/null
import re
import sys
from importlib import metadata
from pathlib import Path

try:
    import tomllib
except ImportError:  # Python 3.10 cannot read pyproject.toml: install to be sure
    sys.exit(1)

root = Path.cwd().resolve()
project = tomllib.loads((root / "pyproject.toml").read_text())["project"]
import sofac  # noqa: E402

if Path(sofac.__file__).resolve().parent != root / "compiler":
    sys.exit(1)
if metadata.version("sofac") != project["version"] or sofac.__version__ != project["version"]:
    sys.exit(1)
scripts = {e.name: e.value for e in metadata.entry_points(group="console_scripts")}
if any(scripts.get(name) != target for name, target in project["scripts"].items()):
    sys.exit(1)  # installed from an older pyproject.toml: its console script points elsewhere
for requirement in [*project["dependencies"], *project["optional-dependencies"]["test"]]:
    metadata.version(re.match(r"[A-Za-z0-9._-]+", requirement).group(0))  # raises when missing
PY
}

if installed_ok; then
    log "sofac $("$PYTHON" -c 'import sofac; print(sofac.__version__)') is installed (editable, with test extras)"
else
    log "installing sofac (editable) with its test extras into $("$PYTHON" -c 'import sys; print(sys.prefix)')"
    PIP_ROOT_USER_ACTION=ignore "$PYTHON" -m pip install --quiet --disable-pip-version-check --no-input \
        -e ".[test]" </dev/null
    installed_ok || { echo "setup: sofac is still not importable after pip install" >&2; exit 1; }
fi

# The host module (the pybind11 bridge to compiled scenes) is built once per installation: build it
# now, so that the first scene only pays for its own compilation.
log "building sofac's host module into its cache (once)"
"$PYTHON" -c "from sofac.build import compiler; compiler.build_host(quiet=True)"
