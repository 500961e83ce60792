#!/usr/bin/env bash
# Renders a ferrosid HTML report with headless Chromium and saves a full-page PNG, to check by
# eye that the report renders (figures, legends, tables). A manual step, not part of the test
# suite (tests parse the HTML and the SVGs instead).
#
#   scripts/screenshot-report.sh [REPORT.html] [OUT.png] [WIDTHxHEIGHT]
#
# Defaults: out/report.html (what `cargo run --release -p ferrosid -- run
# examples/pipeline.toml` writes), out/report.png, 1400x3000 (increase the height to capture
# the whole page; the report is about 7000 px tall).
#
# Needs the Debian package `chromium` (installed here with apt-get when missing and running as
# root). No network access is used: the report is self-contained and the flags below turn off
# Chromium's background traffic.
set -euo pipefail

report="${1:-out/report.html}"
png="${2:-out/report.png}"
size="${3:-1400x3000}"

if [ ! -f "$report" ]; then
    echo "error: $report not found; run: cargo run --release -p ferrosid -- run examples/pipeline.toml" >&2
    exit 2
fi

browser=""
for b in chromium chromium-browser google-chrome; do
    if command -v "$b" >/dev/null 2>&1; then
        browser="$b"
        break
    fi
done
if [ -z "$browser" ]; then
    if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
        echo "installing chromium (apt-get) ..." >&2
        apt-get install -y chromium >/dev/null 2>&1 ||
            { apt-get update >/dev/null 2>&1 && apt-get install -y chromium >/dev/null 2>&1; } ||
            { echo "error: could not install chromium with apt-get" >&2; exit 3; }
        browser=chromium
    else
        echo "error: no chromium found; install it (Debian: sudo apt-get install chromium)" >&2
        exit 3
    fi
fi

abs="$(cd "$(dirname "$report")" && pwd)/$(basename "$report")"
profile="$(mktemp -d)"
trap 'rm -rf "$profile"' EXIT
mkdir -p "$(dirname "$png")"
png_abs="$(cd "$(dirname "$png")" && pwd)/$(basename "$png")"

"$browser" --headless --no-sandbox --disable-gpu --disable-background-networking \
    --disable-component-update --no-first-run --disable-sync --hide-scrollbars \
    --user-data-dir="$profile" --screenshot="$png_abs" --window-size="${size/x/,}" \
    "file://$abs" >/dev/null 2>&1

if [ ! -s "$png_abs" ]; then
    echo "error: chromium wrote no screenshot" >&2
    exit 1
fi
echo "wrote $png_abs"
