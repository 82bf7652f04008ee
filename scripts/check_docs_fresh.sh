#!/usr/bin/env bash
# Build the documentation as a newcomer would: from a copy of the committed tree (git archive HEAD), in a fresh
# virtual environment holding only agentsim's docs extra, with no network while it builds (a network namespace
# of its own when the machine allows one: unshare -n), every warning an error.
#   bash scripts/check_docs_fresh.sh [SCRATCH_FOLDER]
set -euo pipefail
cd "$(dirname "$0")/.."
scratch="${1:-$(mktemp -d)}"
mkdir -p "$scratch/source"
git archive HEAD | tar -x -C "$scratch/source"
python3 -m venv "$scratch/venv"
"$scratch/venv/bin/python" -m pip install -q --disable-pip-version-check "$scratch/source[docs]"
build=("$scratch/venv/bin/python" -m sphinx -W --keep-going -b html -q "$scratch/source/docs" "$scratch/html")
if unshare -n true 2>/dev/null; then
    unshare -n "${build[@]}"
else
    echo "check_docs_fresh: cannot take the network away here (unshare -n); building with it" >&2
    "${build[@]}"
fi
echo "check_docs_fresh: built $scratch/html/index.html"
