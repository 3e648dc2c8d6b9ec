#!/usr/bin/env bash
# Opens a report.html in headless Chromium, checks that every <img> loaded (naturalWidth > 0)
# and that nothing is wider than the page, and takes a full-page screenshot.
#
# Usage: scripts/check_report.sh REPORT.html [SCREENSHOT.png] [WIDTH_PX]
# Exit status: 0 when every check passes, 1 when one fails, 2 on bad usage or a missing tool.
# Needs Debian's `chromium` (apt-get install -y chromium) and python3.
set -euo pipefail

report=${1:?usage: check_report.sh REPORT.html [SCREENSHOT.png] [WIDTH_PX]}
shot=${2:-${report%.html}.png}
width=${3:-1400}
here=$(cd "$(dirname "$0")" && pwd)

if [[ ! -f $report ]]; then
    echo "check_report: $report: no such file" >&2
    exit 2
fi
if ! command -v chromium >/dev/null; then
    echo "check_report: chromium not found (apt-get install -y chromium)" >&2
    exit 2
fi

report_abs=$(cd "$(dirname "$report")" && pwd)/$(basename "$report")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# A copy of the page with the checker injected; <base> keeps its relative image paths working.
python3 "$here/check_report.py" inject "$report_abs" "$work/page.html"

chrome() {
    chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
        --disable-background-networking --disable-component-update --disable-sync \
        --allow-file-access-from-files --user-data-dir="$work/profile" \
        --virtual-time-budget=10000 "$@" 2>"$work/chromium.log"
}

chrome --window-size="$width,4000" --dump-dom "file://$work/page.html" >"$work/dom.html" || {
    echo "check_report: chromium failed; its log:" >&2
    cat "$work/chromium.log" >&2
    exit 2
}
chrome --window-size="$width,4000" --screenshot="$shot" "file://$report_abs" >/dev/null || true
if [[ -s $shot ]]; then
    echo "screenshot: $shot"
else
    echo "check_report: no screenshot written" >&2
fi
python3 "$here/check_report.py" verdict "$work/dom.html"
