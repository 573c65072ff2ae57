#!/usr/bin/env bash
# The page of `rgm register --html` in a real browser: headless Chromium (Debian's package,
# which scripts/setup.sh installs), WebGL in software (SwiftShader). For each page it checks
# that it loads with no error (the page keeps window errors and console.error in #errors), that
# its own self-test (`#selftest`: reads the canvas back, both states) finds a non-blank canvas
# that the before/after toggle changes, and that screenshots of the two states differ.
#
#   bash scripts/test-browser.sh                 # a page of the first partial ModelNet40 test pair
#   bash scripts/test-browser.sh a.html b.html   # these pages instead
#   SCREENSHOT=docs/figures/viewer.png bash scripts/test-browser.sh   # also keep the screenshot
#
# With no pages given it also tests the page of `rgm merge` (the model, a colour per scan) of
# a clean pair of the same shape (or of the synthetic pair).
# The `rgm` binary: $RGM_BIN, else target/debug/rgm (`cargo test --workspace` builds it), else
# target/release/rgm. The ModelNet40 data: $RGM_DATA, else ../shared/data/modelnet40_npy1024;
# without it the page is of a synthetic pair (a helix and its turned copy).
# CI time: about 5 s a page on 2 cores; two pages in CI.
set -euo pipefail
cd "$(dirname "$0")/.."

command -v chromium >/dev/null 2>&1 ||
  { echo "test-browser: no chromium (bash scripts/setup.sh installs it)" >&2; exit 1; }

work=target/browser-test
rm -rf "$work"
mkdir -p "$work"

pages=("$@")
if [ ${#pages[@]} -eq 0 ]; then
  rgm=${RGM_BIN:-}
  for candidate in target/debug/rgm target/release/rgm; do
    [ -z "$rgm" ] && [ -x "$candidate" ] && rgm=$candidate
  done
  [ -n "$rgm" ] || { echo "test-browser: no rgm binary (cargo build first, or set RGM_BIN)" >&2; exit 1; }
  data=${RGM_DATA:-../shared/data/modelnet40_npy1024}
  if [ -d "$data" ]; then
    "$rgm" pairs --setting partial --limit 1 --data "$data" --out "$work/pair" >/dev/null
    source_cloud=$work/pair/0000_source.ply
    target_cloud=$work/pair/0000_target.ply
    # A clean pair (the whole shape twice) for `rgm merge`, which would rightly doubt the
    # partial one.
    "$rgm" pairs --setting clean --limit 1 --data "$data" --out "$work/clean" >/dev/null
    scans=("$work/clean/0000_source.ply" "$work/clean/0000_target.ply")
  else
    echo "test-browser: no ModelNet40 data at $data; a synthetic pair instead"
    python3 - "$work" <<'EOF'
import math, sys
def helix(turn):
    c, s = math.cos(turn), math.sin(turn)
    for i in range(2000):
        a = i * 0.01
        x, y, z = math.cos(3 * a) * (1 + 0.3 * a), math.sin(2 * a), 0.1 * a
        yield c * x - s * y + 0.2, s * x + c * y, z
for name, turn in (("source", 0.4), ("target", 0.0)):
    with open(f"{sys.argv[1]}/{name}.xyz", "w") as out:
        out.writelines(f"{x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in helix(turn))
EOF
    source_cloud=$work/source.xyz
    target_cloud=$work/target.xyz
    scans=("$source_cloud" "$target_cloud")
  fi
  # The default method, as users run it: its transform, candidates and colouring.
  "$rgm" register "$source_cloud" "$target_cloud" --html "$work/page.html" >/dev/null ||
    echo "test-browser: the pair was reported as not registered; its page is tested all the same"
  [ -s "$work/page.html" ] || { echo "test-browser: rgm wrote no page" >&2; exit 1; }
  # Two clouds merged as two scans: the model page (one colour per scan) of `rgm merge`.
  "$rgm" merge "${scans[@]}" --out "$work/merged" >/dev/null 2>&1 ||
    { echo "test-browser: rgm merge placed neither scan" >&2; exit 1; }
  [ -s "$work/merged/model.html" ] || { echo "test-browser: rgm merge wrote no page" >&2; exit 1; }
  pages=("$work/page.html" "$work/merged/model.html")
fi

# Headless Chromium with WebGL on SwiftShader; a fixed window, so that screenshots compare.
browse() {
  timeout 120 chromium --headless=new --no-sandbox --disable-gpu-sandbox \
    --use-angle=swiftshader --enable-unsafe-swiftshader --window-size=1000,650 \
    --hide-scrollbars --virtual-time-budget=10000 --no-first-run --disable-extensions "$@" \
    2>>"$work/chromium.log"
}

failed=0
for page in "${pages[@]}"; do
  url="file://$(realpath "$page")"
  name=$(basename "$page" .html)
  dom=$(browse --dump-dom "$url#selftest")
  verdict=$(grep -o 'selftest {[^<]*}' <<<"$dom" || true)
  errors=$(sed -n 's/.*<pre id="errors"[^>]*>\([^<]*\)<\/pre>.*/\1/p' <<<"$dom")
  browse --screenshot="$work/$name-after.png" "$url" >/dev/null
  browse --screenshot="$work/$name-before.png" "$url#before" >/dev/null
  shots_differ=no
  if [ -s "$work/$name-after.png" ] && [ -s "$work/$name-before.png" ] &&
    ! cmp -s "$work/$name-after.png" "$work/$name-before.png"; then
    shots_differ=yes
  fi
  echo "test-browser: $page ($(($(stat -c %s "$page") / 1000)) KB): ${verdict:-no self-test verdict}; screenshots differ: $shots_differ"
  if [ -n "$errors" ]; then
    echo "test-browser: errors on the page: $errors" >&2
  fi
  if [[ "$verdict" != *'"ok":true'* ]] || [ -n "$errors" ] || [ "$shots_differ" != yes ]; then
    failed=1
  fi
done

if [ "$failed" -ne 0 ]; then
  echo "test-browser: FAILED (chromium's own log: $work/chromium.log)" >&2
  exit 1
fi
if [ -n "${SCREENSHOT:-}" ]; then
  cp "$work/$(basename "${pages[0]}" .html)-after.png" "$SCREENSHOT"
  echo "test-browser: screenshot in $SCREENSHOT"
fi
echo "test-browser: ok, ${#pages[@]} page(s)"
