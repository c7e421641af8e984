# Sourced by the other scripts: chooses the Python interpreter sofac is installed into.
# $PYTHON if set; else the project's .venv (made by setup.sh where the system Python is
# "externally managed", as on Debian 12+ and Ubuntu 23.04+); else python3.
if [[ -z "${PYTHON:-}" ]]; then
    if [[ -x "$PWD/.venv/bin/python" ]]; then
        PYTHON="$PWD/.venv/bin/python"
    else
        PYTHON=python3
    fi
fi
if [[ "$PYTHON" == */bin/python* && -x "$(dirname "$PYTHON")/sofac" ]]; then
    PATH="$(dirname "$PYTHON"):$PATH"  # so that `sofac` is the one installed with $PYTHON
fi
export PYTHON PATH
