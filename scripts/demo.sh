#!/usr/bin/env bash
# The headline job of `make demo`: one closed-loop grasp, as a user runs it.
#
#   `handeye run scenarios/pick_cube.toml --out out/demo` starts the simulator (lockstep,
#   rendering the stereo pair headless) and the daemon as two processes in a private
#   shared-memory domain. The daemon acquires the gripper by opening and closing the jaws,
#   calibrates the cameras on a cage of eight points, plans a grasp on one stereo pair,
#   tracks the chosen facet, servoes the gripper plate coplanar with it, grasps and lifts; the
#   simulator judges the result from ground truth. The report folder gets overlay PNGs of
#   both views at the key moments (trackers drawn), the servo error plot, and the JSONs.
#
#   BIN       the handeye binary    (default target/release/handeye, built by `make build`)
#   SCENARIO  the scenario          (default scenarios/pick_cube.toml)
#   OUT       where the report goes (default out/demo)
set -euo pipefail
cd "$(dirname "$0")/.."

BIN=${BIN:-target/release/handeye}
SCENARIO=${SCENARIO:-scenarios/pick_cube.toml}
OUT=${OUT:-out/demo}

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

echo "demo: handeye run $SCENARIO (simulator + daemon, two processes over shared memory)"
status=0
"$BIN" run "$SCENARIO" --out "$OUT" || status=$?
echo "demo: report in $OUT/: overlays (NN_<moment>.png: both views, trackers drawn), the plan (NN_plan.png,"
echo "      plan.json), servo_convergence.svg, run.json (merged verdict), daemon.json, sim.json, hint.json,"
echo "      daemon.toml, *.stderr.log"
exit $status
