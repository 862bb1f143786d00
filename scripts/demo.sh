#!/usr/bin/env bash
# The headline job of `make demo`, until the daemon arrives: the simulator on pick_cube.toml.
#
#   1. `handeye snapshot` renders the work cell's stereo pair as the cameras see it at the
#      start, with ground truth: out/demo/snapshot/{left,right}.png, truth.json, cage.json.
#   2. `handeye sim --scripted-pick` runs the work cell in real time (30 stereo frames/s on
#      shared memory, robot state every control tick) with the arm driven by a scripted pick
#      that reads the cube's pose from ground truth -- a physics demo: the vision daemon
#      replaces the script in a later issue. `handeye monitor` receives the frames meanwhile.
#   3. `handeye snapshot --scripted-pick --frames 170` renders the cube lifted in the gripper:
#      out/demo/lifted/{left,right}.png.
#
#   BIN       the handeye binary    (default target/release/handeye, built by `make build`)
#   SCENARIO  the scenario          (default scenarios/pick_cube.toml)
#   OUT       where the results go  (default out/demo)
set -euo pipefail
cd "$(dirname "$0")/.."

BIN=${BIN:-target/release/handeye}
SCENARIO=${SCENARIO:-scenarios/pick_cube.toml}
OUT=${OUT:-out/demo}
DOMAIN=demo-$$   # a private shared-memory domain: never mixes with a running system

if [ ! -x "$BIN" ]; then
    echo "demo: $BIN is missing; run \`make demo\` (it builds it) or \`cargo build --release\`" >&2
    exit 1
fi
mkdir -p "$OUT"
if [ -z "${XDG_RUNTIME_DIR:-}" ]; then
    # Mesa's Vulkan driver wants one (it probes for a display); any private directory will do.
    export XDG_RUNTIME_DIR="$(cd "$OUT" && pwd)/.xdg"
    mkdir -p -m 700 "$XDG_RUNTIME_DIR"
fi

monitor_pid=""
cleanup() {
    if [ -n "$monitor_pid" ] && kill -0 "$monitor_pid" 2>/dev/null; then
        kill -INT "$monitor_pid" 2>/dev/null || true
        wait "$monitor_pid" 2>/dev/null || true
    fi
    monitor_pid=""
    # iceoryx2 keeps one small management segment per domain; this private one is done.
    rm -f /dev/shm/iox2_"$DOMAIN"_* 2>/dev/null || true
}
trap cleanup EXIT

echo "demo: rendering $SCENARIO as the cameras see it"
"$BIN" snapshot "$SCENARIO" --out "$OUT/snapshot"

echo "demo: running the simulator in real time with a scripted pick (frames on shared memory, domain $DOMAIN)"
"$BIN" monitor --domain "$DOMAIN" --timeout 0 --progress 0 --report "$OUT/monitor.json" >"$OUT/monitor.txt" 2>"$OUT/monitor.log" &
monitor_pid=$!
sleep 0.5
"$BIN" sim "$SCENARIO" --scripted-pick --domain "$DOMAIN" --json >"$OUT/sim.json" 2>"$OUT/sim.log"
sleep 0.3
cleanup

echo "demo: rendering the lifted cube"
"$BIN" snapshot "$SCENARIO" --scripted-pick --frames 170 --out "$OUT/lifted"

python_summary() {
    python3 - "$OUT/sim.json" "$OUT/monitor.json" <<'EOF'
import json, sys
sim = json.load(open(sys.argv[1]))
mon = json.load(open(sys.argv[2]))
v = sim["verdict"]
verdict = f"SUCCESS at {v['success']['at_ns'] / 1e9:.2f} s" if isinstance(v, dict) else v
print(f"demo: {sim['scenario']}: {verdict} (cube lifted {sim['max_lift_mm']:.0f} mm), "
      f"{sim['frames']} stereo frames published at {sim['fps']:.1f} frames/s; "
      f"monitor received {mon['frames']} frames, {mon['rejected']} rejected, "
      f"latency p50 {mon['latency_ns_p50'] / 1e3:.0f} us")
EOF
}
if command -v python3 >/dev/null 2>&1; then
    python_summary
else
    echo "demo: simulator report:"; cat "$OUT/sim.json"; echo
fi
echo "demo: done. Images: $OUT/snapshot/{left,right}.png (start), $OUT/lifted/{left,right}.png (cube lifted);"
echo "      ground truth: $OUT/snapshot/truth.json, cage.json; reports: $OUT/sim.json, $OUT/monitor.json"
