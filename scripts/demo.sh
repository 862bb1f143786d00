#!/usr/bin/env bash
# The headline job of `make demo`. Until the simulator exists it is the camera path alone:
# `handeye feed` publishes the real cube sequence on shared memory like a 30 frames/s stereo
# camera (the same image as both views), and `handeye monitor` receives 200 frames and reports
# rate, gaps, rejections and transport latency.
#
#   BIN   the handeye binary   (default target/release/handeye, built by `make build`)
#   DATA  the image sequence   (default ../shared/data/visp-cube)
#   OUT   where the report goes (default out/demo)
set -euo pipefail
cd "$(dirname "$0")/.."

BIN=${BIN:-target/release/handeye}
DATA=${DATA:-../shared/data/visp-cube}
OUT=${OUT:-out/demo}
DOMAIN=demo-$$   # a private shared-memory domain: never mixes with a running system

if [ ! -x "$BIN" ]; then
    echo "demo: $BIN is missing; run \`make demo\` (it builds it) or \`cargo build --release\`" >&2
    exit 1
fi
if ! ls "$DATA"/*.png >/dev/null 2>&1; then
    echo "demo: no PNG images in $DATA; set DATA=/path/to/images (a flat folder of same-size PNGs)" >&2
    exit 1
fi
mkdir -p "$OUT"

feed_pid=""
cleanup() {
    if [ -n "$feed_pid" ] && kill -0 "$feed_pid" 2>/dev/null; then
        kill -INT "$feed_pid" 2>/dev/null || true
        wait "$feed_pid" 2>/dev/null || true
    fi
    feed_pid=""
    # iceoryx2 keeps one small management segment per domain; this private one is done.
    rm -f /dev/shm/iox2_"$DOMAIN"_* 2>/dev/null || true
}
trap cleanup EXIT

echo "demo: feeding $DATA at 30 frames/s on shared memory (domain $DOMAIN)"
"$BIN" feed --domain "$DOMAIN" --mono --loop --rate 30 --dir "$DATA" 2>"$OUT/feed.log" &
feed_pid=$!

echo "demo: monitoring 200 frames (about 7 s)"
"$BIN" monitor --domain "$DOMAIN" --count 200 --timeout 30 --report "$OUT/monitor.json" | tee "$OUT/monitor.txt"

cleanup
echo "demo: done. Report: $OUT/monitor.json (summary: $OUT/monitor.txt, feed log: $OUT/feed.log)"
