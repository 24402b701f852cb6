#!/usr/bin/env bash
# Colour-constant stereo visual teach & repeat, launch-free, across processes: vtr_localizer_node teaches a route
# from a bag played with `lightfast bag play`, the teach is finished with the /vtr/finish_teach service (the map is
# written atomically), then a second vtr_localizer_node process repeats the route from another bag while
# `lightfast bag record` records its output; prints how many stereo pairs localized and, when the bags hold
# /ground_truth/pose, the localization error against the truth. Ctrl-C stops every process this script started.
#
# Usage: scripts/vtr_demo.sh [TEACH_BAG REPEAT_BAG]
#   The bags hold /stereo/{left,right}/image_raw (rgb8, rectified) and /stereo/{left,right}/camera_info (e.g. the
#   runs of `lightfast sim vtr`; optionally /ground_truth/pose). Without arguments the script renders (once, then
#   reuses) a short simulated route with `lightfast sim vtr`: the teach run and REPEAT_RUN.
#
# Environment (all optional):
#   LIGHTFAST_OUT    output directory (default ./out): the map, the recorded repeat output, the node logs
#   MODE             repeat localization: fused | grey | mcmanus (default fused)
#   RATE             playback rate (default 1 = real time; the node drops pairs it cannot keep up with in the repeat)
#   LENGTH, SIZE     simulated route length in metres and image size WxH (default 40 and 320x240)
#   REPEAT_RUN       simulated repeat to use (default repeat07: shadows opposite to the map's)
#   SENSOR_RELIABILITY  the node's sensor_reliability (default reliable: a replay loses nothing)
#   ROS_DOMAIN_ID    DDS domain (default: a random id)
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bash "$root/scripts/setup.sh"
bin="$root/.venv/bin"
lf="$bin/lightfast"
out=${LIGHTFAST_OUT:-$root/out}
mode=${MODE:-fused}
rate=${RATE:-1}
sensor=${SENSOR_RELIABILITY:-reliable}  # a replay loses nothing; a live camera driver is best_effort
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$(( (RANDOM % 82) + 20 ))}
mkdir -p "$out"
out=$(cd "$out" && pwd)

if [ $# -eq 2 ]; then
  teach_bag=$1
  repeat_bag=$2
elif [ $# -eq 0 ]; then
  length=${LENGTH:-40}
  size=${SIZE:-320x240}
  repeat_run=${REPEAT_RUN:-repeat07}
  sim="$out/vtr-sim-$length-$size"
  echo "== simulating the teach run and $repeat_run ($length m, $size) in $sim (reused when complete)"
  "$lf" sim vtr "$sim" --runs teach "$repeat_run" --length "$length" --size "$size"
  teach_bag="$sim/teach/bag"
  repeat_bag="$sim/$repeat_run/bag"
else
  echo "usage: $0 [TEACH_BAG REPEAT_BAG]" >&2
  exit 2
fi
for bag in "$teach_bag" "$repeat_bag"; do
  [ -e "$bag" ] || { echo "vtr_demo: error: no bag at $bag" >&2; exit 1; }
done

map="$out/vtr-map"
recorded="$out/vtr-repeat-output"
logs="$out/vtr-logs"
mkdir -p "$logs"
stereo=(/stereo/left/image_raw /stereo/right/image_raw /stereo/left/camera_info /stereo/right/camera_info)

source "$(dirname "${BASH_SOURCE[0]}")/processes.sh"
node_failed() {  # the node's log tells why
  echo "vtr_demo: error: the $1 step failed; last lines of $logs/$1.log:" >&2
  tail -n 20 "$logs/$1.log" >&2
  exit 1
}

echo "== teach: vtr_localizer_node on $teach_bag -> $map (domain $ROS_DOMAIN_ID, logs in $logs)"
# a teach should lose no pair: a long queue
"$bin/vtr_localizer_node" --ros-args -p mode:=teach -p map_path:="$map" -p overwrite_map:=true \
  -p max_queued_frames:=10000 -p sensor_reliability:="$sensor" >"$logs/teach.log" 2>&1 &
teach_pid=$!
pids+=("$teach_pid")
"$lf" vtr wait-idle --pid "$teach_pid" --settle 0 --timeout 120 >/dev/null || node_failed teach
"$lf" bag play "$teach_bag" --rate "$rate" --wait-for-subscribers 120 --topics "${stereo[@]}"
"$lf" vtr finish-teach --pid "$teach_pid" --settle 2 --timeout 600 || node_failed teach
stop "$teach_pid"

echo "== repeat ($mode): vtr_localizer_node on $repeat_bag against $map, output recorded to $recorded"
"$bin/vtr_localizer_node" --ros-args -p mode:=repeat -p map_path:="$map" -p repeat.mode:="$mode" \
  -p sensor_reliability:="$sensor" \
  >"$logs/repeat.log" 2>&1 &
repeat_pid=$!
pids+=("$repeat_pid")
"$lf" bag record --overwrite -o "$recorded" /vtr/localization /vtr/odometry /vtr/status >"$logs/record.log" 2>&1 &
recorder=$!
pids+=("$recorder")
"$lf" vtr wait-idle --pid "$repeat_pid" --settle 0 --timeout 120 --subscribers /vtr/localization /vtr/odometry \
  >/dev/null || node_failed repeat
"$lf" bag play "$repeat_bag" --rate "$rate" --wait-for-subscribers 120 --topics "${stereo[@]}"
"$lf" vtr wait-idle --pid "$repeat_pid" --settle 2 --timeout 600 || node_failed repeat
stop "$recorder"
stop "$repeat_pid"

echo "== result ($mode)"
if [ -e "$recorded" ]; then
  "$lf" vtr summary "$recorded" --map "$map" --teach-bag "$teach_bag" --repeat-bag "$repeat_bag"
else
  echo "vtr_demo: error: nothing was recorded (see $logs/record.log)" >&2
  exit 1
fi
