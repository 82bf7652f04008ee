#!/usr/bin/env bash
# Vendors three.js for the HTML run report (agentsim/media/report): installs `three` and `esbuild` from the
# npm registry into a temporary folder, bundles three with its OrbitControls addon into one minified IIFE
# that sets the global `THREE` (with `THREE.OrbitControls`), and writes it, with three's MIT licence, to
# agentsim/media/report/vendor/. A report is opened from file:// with no network, where Chromium loads
# neither ES modules nor fetch(), so the page needs one classic script.
#
#   bash scripts/vendor_three.sh [THREE_VERSION]      (default: the version pinned below)
set -euo pipefail
cd "$(dirname "$0")/.."
THREE_VERSION="${1:-0.187.0}"
ESBUILD_VERSION="0.28.2"
OUT=agentsim/media/report/vendor
WORK="$(mktemp -d /tmp/vendor-three.XXXXXX)"
trap 'rm -rf "$WORK"' EXIT
(
    cd "$WORK"
    npm init -y >/dev/null
    npm install --silent --no-audit --no-fund "three@$THREE_VERSION" "esbuild@$ESBUILD_VERSION"
    cat > entry.js <<'JS'
import * as core from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
window.THREE = Object.assign({}, core, { OrbitControls });
JS
    npx esbuild entry.js --bundle --minify --format=iife --target=es2020 --legal-comments=none \
        --log-level=warning --outfile=three.min.js
)
VERSION="$(node -p "require('$WORK/node_modules/three/package.json').version")"
mkdir -p "$OUT"
{
    printf '/* three.js %s (https://threejs.org) with its OrbitControls addon, bundled as one IIFE that sets\n' "$VERSION"
    printf '   window.THREE (and THREE.OrbitControls) by scripts/vendor_three.sh.\n'
    printf '   %s. MIT licence: LICENSE-three.txt. */\n' "$(grep -m1 Copyright "$WORK/node_modules/three/LICENSE")"
    cat "$WORK/three.min.js"
} > "$OUT/three.min.js"
cp "$WORK/node_modules/three/LICENSE" "$OUT/LICENSE-three.txt"
echo "three $VERSION -> $OUT/three.min.js ($(wc -c < "$OUT/three.min.js") bytes)"
