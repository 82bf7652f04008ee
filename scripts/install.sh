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
# is 3.11 or newer, else from the python3 first on the PATH; PYTHON=/path/to/python names another. Debian's is a
# statically linked, optimised build: where python3 is another build (pyenv's, with a shared libpython), the
# same run takes about a sixth longer with it.
if [ -z "${PYTHON:-}" ]; then
    PYTHON=python3
    if [ -x /usr/bin/python3 ] && /usr/bin/python3 -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
        PYTHON=/usr/bin/python3
    fi
fi
[ -x .venv/bin/python ] || "$PYTHON" -m venv .venv
.venv/bin/python -m pip install -q --disable-pip-version-check -e '.[test,docs,piper]'
