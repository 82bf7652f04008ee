#!/usr/bin/env bash
# Prints the interpreter scripts/install.sh makes .venv from: AGENTSIM_PYTHON if it is set, else Debian's own
# Python 3 (/usr/bin/python3, the one the python3-venv and python3-pip packages are for) if it is 3.11 or newer,
# else the python3 first on the PATH. Debian's is a statically linked, optimised build: where python3 is another
# build (pyenv's, with a shared libpython), the same run takes a sixth to a fifth longer with it. One that is not
# Python 3.11 or newer is refused (exit status 1), with a line on stderr saying how to name another.
set -euo pipefail
new_enough() { "$1" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; }
PYTHON="${AGENTSIM_PYTHON:-}"
if [ -z "$PYTHON" ]; then
    PYTHON=python3
    if [ -x /usr/bin/python3 ] && new_enough /usr/bin/python3; then
        PYTHON=/usr/bin/python3
    fi
fi
if ! new_enough "$PYTHON"; then
    echo "install.sh: $PYTHON is not Python 3.11 or newer: install it, or name one with" \
         "AGENTSIM_PYTHON=/path/to/python3" >&2
    exit 1
fi
echo "$PYTHON"
