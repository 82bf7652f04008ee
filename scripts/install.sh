#!/usr/bin/env bash
# Installs what agentsim needs: Debian packages (espeak-ng, Festival with its HTS and diphone US voices,
# FluidSynth with a General MIDI soundfont, PortAudio, PulseAudio, and Chromium, which the system tests open run reports in) and the Python packages,
# in a virtual environment at .venv, with the extras for the tests, the documentation and Piper's voice.
set -euo pipefail
cd "$(dirname "$0")/.."
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO=sudo
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq python3-venv python3-pip espeak-ng espeak-ng-data libespeak-ng1 \
    festival festvox-us-slt-hts festvox-kallpc16k \
    fluidsynth libfluidsynth3 fluid-soundfont-gm libportaudio2 pulseaudio libasound2-plugins chromium >/dev/null
# The environment is made from Debian's own Python 3 (the one python3-venv and python3-pip above are for), if it
# is 3.11 or newer, else from the python3 first on the PATH; AGENTSIM_PYTHON=/path/to/python3 names another.
# Debian's is a statically linked, optimised build: where python3 is another build (pyenv's, with a shared
# libpython), the same run takes a sixth to a fifth longer with it. A .venv made before is kept as it is.
new_enough() { "$1" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; }
if [ ! -x .venv/bin/python ]; then
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
    "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install -q --disable-pip-version-check -e '.[test,docs,piper]'
