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
# The environment is made from the interpreter scripts/venv_python.sh chooses (Debian's own Python 3, or the one
# AGENTSIM_PYTHON names); a .venv made before is kept as it is.
if [ ! -x .venv/bin/python ]; then
    PYTHON="$(bash scripts/venv_python.sh)"
    "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install -q --disable-pip-version-check -e '.[test,docs,piper]'
