#!/usr/bin/env bash
# Active camera relocalization (rACR), launch-free, across processes: the simulated robotic platform
# (racr_platform_sim_node), the VSE stand-in that renders the scene by ray casting (racr_vse_node) and racr_node
# run as three processes; racr_node issues the initialization motions, recovers the hand-eye transform and the real
# scale, then aligns and adjusts until it converges; the script then prints the final AFD against the reference
# image, the camera pose error against the reference pose (both from the simulator's truth), the motions and the
# simulated platform time. Ctrl-C stops every process this script started.
#
# Usage: scripts/racr_demo.sh [SCENE_DIR]
#   SCENE_DIR is a scene directory of `lightfast sim racr` (racr_node reads only its reference/). Without it the
#   script renders (once, then reuses) scene $SCENE with `lightfast sim racr`.
#
# Environment (all optional):
#   LIGHTFAST_OUT  output directory (default ./out): the scene and the node logs
#   SCENE          simulated scene S01..S20 (default S01: a carved relief panel under a point light)
#   SIZE           image size WxH (default 320x240); RESOLUTION mesh vertex step in m (default 0.005)
#   LIGHTING       lighting of the session: reference | similar | varied (default varied: a grazing side light)
#   MODE           parallel | serial (default parallel)
#   TIME_SCALE     platform speed-up: simulated seconds per wall second (default 10; 1 = the paper's 1.5 s/cm)
#   ETA            convergence threshold of g = ||M_B - I||_F (default 1e-3; the paper's 1e-4 is beyond what the
#                  estimate resolves at small image sizes, so the run would never stop)
#   SEED           seed of the platform's mechanical error; the VSE stand-in uses SEED + 1 (default 0)
#   TIMEOUT        give up after this many seconds (default 300)
#   SENSOR_RELIABILITY  racr_node's sensor_reliability (default reliable: lossless; racr_node's own default is best_effort)
#   ROS_DOMAIN_ID  DDS domain (default: a random id)
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bash "$root/scripts/setup.sh"
bin="$root/.venv/bin"
out=${LIGHTFAST_OUT:-$root/out}
scene_name=${SCENE:-S01}
size=${SIZE:-320x240}
resolution=${RESOLUTION:-0.005}
lighting=${LIGHTING:-varied}
mode=${MODE:-parallel}
decimal() {  # ROS parameters are typed: a double needs a decimal point (20 -> 20.000000000000)
  awk -v x="$1" 'BEGIN { printf "%.12f", x }'
}
time_scale=$(decimal "${TIME_SCALE:-10}")
eta=$(decimal "${ETA:-1e-3}")
timeout_s=${TIMEOUT:-300}
seed=${SEED:-0}
sensor=${SENSOR_RELIABILITY:-reliable}  # lossless; best_effort is the default of racr_node for live VSEs
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$(( (RANDOM % 82) + 20 ))}
mkdir -p "$out"
out=$(cd "$out" && pwd)

if [ $# -eq 1 ]; then
  scene=$1
elif [ $# -eq 0 ]; then
  sim="$out/racr-sim-$size-$resolution"
  echo "== simulating scene $scene_name ($size, mesh step $resolution m) in $sim (reused when complete)"
  "$bin/lightfast" sim racr "$sim" --only "$scene_name" --size "$size" --resolution "$resolution" --no-progress
  scene="$sim/$scene_name"
else
  echo "usage: $0 [SCENE_DIR]" >&2
  exit 2
fi
[ -f "$scene/reference/reference.yaml" ] || { echo "racr_demo: error: no scene at $scene" >&2; exit 1; }
scene=$(cd "$scene" && pwd)
scene_name=$(basename "$scene")
logs="$out/racr-logs"
mkdir -p "$logs"

source "$(dirname "${BASH_SOURCE[0]}")/processes.sh"

echo "== rACR on $scene_name under the '$lighting' lighting ($mode, time scale ${TIME_SCALE:-10}, eta ${ETA:-1e-3}," \
     "seed $seed; domain $ROS_DOMAIN_ID, logs in $logs)"
"$bin/racr_platform_sim_node" --ros-args -p scene_path:="$scene" -p time_scale:="$time_scale" -p seed:="$seed" \
  >"$logs/platform.log" 2>&1 &
pids+=("$!")
"$bin/racr_vse_node" --ros-args -p scene_path:="$scene" -p lighting:="$lighting" -p seed:="$((seed + 1))" \
  >"$logs/vse.log" 2>&1 &
pids+=("$!")
"$bin/racr_node" --ros-args -p reference_path:="$scene/reference" -p reference_scene:="$scene_name" \
  -p scheme.mode:="$mode" -p adjustment.eta:="$eta" -p sensor_reliability:="$sensor" >"$logs/racr.log" 2>&1 &
pids+=("$!")

rc=0
"$bin/lightfast" racr wait --scene "$scene" --timeout "$timeout_s" --pid "${pids[@]}" || rc=$?
if [ "$rc" -eq 130 ]; then
  echo "interrupted"
  exit 130
elif [ "$rc" -ne 0 ]; then
  for name in racr platform vse; do
    echo "-- last lines of $logs/$name.log" >&2
    tail -n 15 "$logs/$name.log" >&2
  done
  exit 1
fi
