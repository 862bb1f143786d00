#!/usr/bin/env bash
# Batches and a render check on a lent GPU machine (the `device` tool; see STATUS.md, issue 20).
# Here: strip a `cargo build --release --no-default-features --bin handeye` into devbin/handeye,
# copy this script to devbin/run.sh, download the Vulkan loader debs into .gl (device README), and
# ignore both in .git/info/exclude. There: BATCHES="rand50 clutter30" JOBS=12 bash devbin/run.sh check
# (modes: check = snapshot + bench render, none); TRACK=1 also times devbin/tracker_profile_{base,new};
# FIRST=31 starts the point30/given30 batches at seed 31 (unseen seeds). ACROSS=1 keeps each run's
# servo debug log (EXTRA="--config F" adds batch options) and writes every servo step's mark parallax across the epipolar lines to
# $OUT/<batch>.across.txt (seed, step, across px).
set -u
MODE=${1:-check}
for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig
export XDG_RUNTIME_DIR=$(mktemp -d)
nvidia-smi -L 2>&1 | head -2
nproc
if ! ls /usr/share/vulkan/icd.d/*.json /etc/vulkan/icd.d/*.json >/dev/null 2>&1; then
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
  export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
  echo "VK_DRIVER_FILES set"
fi
B=${BIN:-devbin/handeye}; chmod +x $B
J=${JOBS:-12}
t0=$(date +%s)
if [ "$MODE" = check ]; then
  $B snapshot scenarios/pick_cube.toml --out $OUT/snap 2>&1 | tail -3
  $B bench render scenarios/pick_cube.toml --json > $OUT/render_gpu.json 2> $OUT/render.err; echo "render rc $?"; cat $OUT/render_gpu.json | head -c 1500; echo
  echo "t=$(( $(date +%s) - t0 )) s"
fi
for b in ${BATCHES:-}; do
  case $b in
    rand50) args="--randomize --seeds 50";;
    clutter30) args="scenarios/clutter3.toml --seeds 30";;
    point30) args="scenarios/point_clutter3.toml --seeds 30 --first-seed ${FIRST:-1}";;
    given30) args="scenarios/point_clutter3.toml --seeds 30 --first-seed ${FIRST:-1} --given-point";;
    c100) args="scenarios/clutter3.toml --seeds 30 --first-seed 100";;
    disturb30) args="scenarios/clutter3.toml --seeds 30 --disturb";;
  esac
  n=$b${FIRST:+_f$FIRST}
  keep=""
  if [ -n "${ACROSS:-}" ]; then export HANDEYE_LOG="warn,handeye_daemon::phase::servo=debug"; keep="--out /tmp/runs/$n"; fi
  timeout ${BT:-200} $B batch $args ${EXTRA:-} --jobs $J --json $keep > $OUT/$n.json 2> $OUT/$n.err; echo "$n rc $? t=$(( $(date +%s) - t0 )) s"
  if [ -n "${ACROSS:-}" ]; then
    for d in /tmp/runs/$n/*/seed-*; do
      sed 's/\x1b\[[0-9;]*m//g' $d/daemon.stderr.log | grep -o "servo step step=[0-9]* .*across=\[[^]]*\]" | sed "s|^|${d##*seed-} |; s/ frame=.*across=/ /" >> $OUT/$n.across.txt
    done
    sed 's/\x1b\[[0-9;]*m//g' /tmp/runs/$n/*/seed-*/daemon.stderr.log 2>/dev/null | grep -c "parallax" | sed 's/^/parallax failures: /'
  fi
  python3 -c "
import json; d=json.load(open('$OUT/$n.json'))
print('$n', {k:d.get(k) for k in ['runs','successes','graspable_runs','graspable_successes','correct_refusals','ungraspable_runs','attempts_on_ungraspable','wrong_refusals','median_run_wall_s']})
for r in d['runs_detail']:
    s=r['summary']
    if not s['success']: print('  fail', s['seed'], (s.get('failure_reason') or '')[:100])
print('$n', {k:d.get(k) for k in ['runs','successes','graspable_runs','graspable_successes','correct_refusals','ungraspable_runs','attempts_on_ungraspable','wrong_refusals']})
" 2>&1 | tail -60
  tail -c 300 $OUT/$n.err
done
echo "total t=$(( $(date +%s) - t0 )) s"
if [ -n "${TRACK:-}" ]; then
  for i in 1 2 3; do for v in base new; do
    echo -n "$v: "; devbin/tracker_profile_$v devbin/visp-cube 10 2>&1 | grep -i "stereo" | head -2 | tr '\n' ' '; echo
  done; done
fi
