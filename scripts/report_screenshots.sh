#!/bin/sh
# Screenshots of a report page, one per part, as a person sees them: headless
# Chromium (Debian `chromium`) renders a copy of index.html in which a style
# rule shows only that part (header, slices and checkerboard; convergence and
# metrics; the run graph drawn; its [tune] tables and the first six stages'
# parameters), so each PNG starts at its part without scrolling or cropping.
#
#   sh scripts/report_screenshots.sh OUT/report/index.html DEST_DIR [WIDTH]
#
# writes DEST_DIR/report-slices.png, report-convergence.png, report-graph.png,
# report-parameters.png.
# Used for docs/report/ (the demo's page: make demo, then this script).
set -eu
page=${1:?usage: report_screenshots.sh PAGE DEST_DIR [WIDTH]}
dest=${2:?usage: report_screenshots.sh PAGE DEST_DIR [WIDTH]}
width=${3:-1400}
command -v chromium >/dev/null || { echo "report_screenshots: chromium not found (apt-get install chromium)" >&2; exit 2; }
[ -f "$page" ] || { echo "report_screenshots: no page $page" >&2; exit 2; }
mkdir -p "$dest"
dir=$(cd "$(dirname "$page")" && pwd)
dest=$(cd "$dest" && pwd)
tmp="$dir/.shot-$$.html"
trap 'rm -f "$tmp"' EXIT INT TERM

# height CSS: the page's height in px with CSS added, as Chromium lays it out
# at $width (a script writes it into the DOM, which --dump-dom prints)
height() {
    sed -e "s|</style>|$1</style>|" \
        -e 's|</body>|<script>document.body.setAttribute("data-h",document.documentElement.scrollHeight)</script></body>|' \
        "$page" > "$tmp"
    chromium --headless --no-sandbox --disable-gpu --hide-scrollbars \
        --force-device-scale-factor=1 --window-size="$width,800" \
        --dump-dom "file://$tmp" 2>/dev/null |
        sed -n 's/.*data-h="\([0-9]*\)".*/\1/p' | head -1
}

# shot NAME CSS: the page with CSS added, as tall as its content (at most
# 6000 px), so a part is never cut off and nothing empty follows it
shot() {
    h=$(height "$2")
    [ -n "$h" ] || { echo "report_screenshots: chromium gave no page height for $1" >&2; exit 1; }
    [ "$h" -le 6000 ] || h=6000
    sed "s|</style>|$2</style>|" "$page" > "$tmp"
    chromium --headless --no-sandbox --disable-gpu --hide-scrollbars \
        --force-device-scale-factor=1 --window-size="$width,$h" \
        --screenshot="$dest/$1" "file://$tmp" >/dev/null 2>&1
    [ -s "$dest/$1" ] || { echo "report_screenshots: chromium wrote no $1" >&2; exit 1; }
    echo "wrote $dest/$1 ($width x $h px)"
}

shot report-slices.png \
    'nav,#convergence,#metrics,#graph,#tables{display:none}'
shot report-convergence.png \
    'header,nav,#slices,#checker,#graph,#tables{display:none}'
shot report-graph.png \
    'header,nav,#slices,#checker,#convergence,#metrics,#tables,#graph>table,#graph>h3,#graph .cards{display:none}'
shot report-parameters.png \
    'header,nav,#slices,#checker,#convergence,#metrics,#tables,figure.dagfig,#graph .card:nth-child(n+7){display:none}'
