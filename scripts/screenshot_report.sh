#!/usr/bin/env bash
# Renders a calibration report in headless Chromium (Debian package `chromium`, not part of the
# build's dependencies) and saves a screenshot: scripts/screenshot_report.sh REPORT.html OUT.png [HEIGHT]
set -euo pipefail
html=$(realpath "$1"); png=$2; height=${3:-2400}
command -v chromium > /dev/null || { echo "screenshot_report: needs chromium (apt-get install chromium)" >&2; exit 2; }
chromium --headless --no-sandbox --disable-gpu --hide-scrollbars --window-size=1200,"$height" \
  --screenshot="$(realpath -m "$png")" "file://$html" 2> /dev/null
echo "wrote $png"
