#!/usr/bin/env bash
# The main job, launch-free: set up; generate (or reuse) a short simulated daylight recording and its lighting map;
# start sun_update_node, daylight_relight_node and rgbd_tracker_node as separate processes on sim time; replay the
# recording with /clock while `lightfast bag record` records what the nodes publish; then print RMSE, tracking loss,
# throughput, latency and the per-stage timings (paper Table II). Ctrl-C stops every process this script started.
#
# Environment (all optional):
#   LIGHTFAST_OUT    output directory (default ./out)
#   SEQUENCE         recording to simulate (default DS1.T6, cloudy: the brightness changes while you watch)
#   FRAMES           frames to simulate at 30 Hz (default 300)
#   SIZE             image size WxH (default 320x240)
#   RESOLUTION       scene mesh resolution in metres (default 0.04: a quick first run)
#   PATCH_SIZE       lighting-map patch size in metres (default 0.1, as in the paper)
#   SUN_UPDATE_PERIOD  seconds between B̂_sun updates (default 60; small values keep sun chunks streaming)
#   PREROLL          seconds the clock runs before the first frame, for the first sun update (default 30)
#   MODE             tracker mode: proposed | refl-f2m | depth-only | no-color-f2m (default proposed)
#   RATE             playback rate (default 1 = real time)
#   PLAYS            how many times the recording is played, one `lightfast bag play` after the other (default 1;
#                    each play after the first sends time back: the nodes start over, the scores are per play)
#   PLAY_ARGS        extra `lightfast bag play` options, e.g. "--loops 2" or "--reliability best_effort"
#   SENSOR_RELIABILITY  the nodes' sensor_reliability (default reliable: a replay loses nothing; a live camera
#                    driver is best_effort, the nodes' default)
#   TRACKER_PARAMS   extra rgbd_tracker_node parameters, e.g. "finest_point_step:=2 f2m_iterations:=[4,3,2]"
#   RECORD_TOPICS    topics to record (default: what the scoring reads, /tracker/pose, both status topics, the sun
#                    chunks and direction; "all": also the coarse pose, odometry and the brightness scales)
#   ROS_DOMAIN_ID    DDS domain (default: a random id)
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bash "$root/scripts/setup.sh"
bin="$root/.venv/bin"
lf="$bin/lightfast"
out=${LIGHTFAST_OUT:-$root/out}
sequence=${SEQUENCE:-DS1.T6}
frames=${FRAMES:-300}
size=${SIZE:-320x240}
resolution=${RESOLUTION:-0.04}
patch_size=${PATCH_SIZE:-0.1}
preroll=${PREROLL:-30}
sun_period=${SUN_UPDATE_PERIOD:-60.0}
[[ $sun_period == *.* ]] || sun_period="$sun_period.0"  # a double parameter
mode=${MODE:-proposed}
rate=${RATE:-1}
plays=${PLAYS:-1}
sensor=${SENSOR_RELIABILITY:-reliable}
read -r -a play_args <<<"${PLAY_ARGS:-}"
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$(( (RANDOM % 82) + 20 ))}
# one BLAS/OpenMP thread per process: five processes share 2 cores, and idle BLAS workers spin on them
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1} OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
sim="$out/daylight-sim-$size-$frames-$resolution"
scene=${sequence%%.*}
seq_dir="$sim/$sequence"
mkdir -p "$out"

echo "== recording $sequence ($frames frames, $size) in $sim (reused when complete)"
"$lf" sim daylight "$sim" --sequences "$sequence" --frames "$frames" --size "$size" --resolution "$resolution"
# the method's map is the simulator's reconstruction of a depth scan (scenes/<scene>.map.ply), never the true mesh
# with the window declared (scenes/<scene>.openings.yaml), so that light enters only through it
map_ply="$sim/scenes/$scene.map.ply"
openings="$sim/scenes/$scene.openings.yaml"
# the map format version is part of the name: a map made by an older lightfast is prepared again, not refused
map_version=$("$bin/python" -c 'from lightfast.daylight.lighting_map import FORMAT_VERSION; print(FORMAT_VERSION)')
map="$sim/maps/$scene-$patch_size-v$map_version-$(cat "$map_ply" "$openings" | sha1sum | cut -c1-12)"
if [ ! -f "$map/metadata.json" ]; then
  echo "== preparing the lighting map of $scene in $map"
  "$lf" daylight prepare "$map_ply" "$sim/scenes/$scene.site.yaml" "$map" --patch-size "$patch_size" \
    --openings "$openings"
fi
initial_pose=$("$lf" bag pose "$seq_dir/bag")  # the evaluation protocol's known start pose

source "$(dirname "${BASH_SOURCE[0]}")/processes.sh"

logs="$out/demo-logs"
mkdir -p "$logs"
echo "== starting the nodes (domain $ROS_DOMAIN_ID, logs in $logs)"
# the sun update is a background job (its chunks are used once an epoch is complete): it yields the CPU to tracking
nice -n 19 "$bin/sun_update_node" --ros-args -p use_sim_time:=true -p lighting_map:="$map" -p update_period_s:="$sun_period" \
  -p patches_per_step:=2000 >"$logs/sun_update_node.log" 2>&1 &
pids+=($!)
"$bin/daylight_relight_node" --ros-args -p use_sim_time:=true -p sensor_reliability:="$sensor" -p lighting_map:="$map" \
  -p crf_file:="$seq_dir/camera.yaml" -p reference:="$([ "$mode" = refl-f2m ] && echo reflectance || echo relit)" \
  >"$logs/daylight_relight_node.log" 2>&1 &
pids+=($!)
tracker_params=()
for kv in ${TRACKER_PARAMS:-}; do tracker_params+=(-p "$kv"); done
"$bin/rgbd_tracker_node" --ros-args -p use_sim_time:=true -p sensor_reliability:="$sensor" -p mode:="$mode" \
  -p initial_pose:="$initial_pose" \
  "${tracker_params[@]}" \
  >"$logs/rgbd_tracker_node.log" 2>&1 &
pids+=($!)

recorded="$out/demo-output"
# the recorder is one more process on the two cores: by default it takes only what the scoring below reads
topics=(/tracker/pose /tracker/status /relight/status /sun/direction /radiosity/sun_chunk)
if [[ "${RECORD_TOPICS:-}" == all ]]; then
  topics+=(/tracker/coarse_pose /tracker/odometry /relight/scale/sun /relight/scale/sky /relight/scale/ground)
elif [[ -n "${RECORD_TOPICS:-}" ]]; then
  read -r -a topics <<<"$RECORD_TOPICS"
fi
"$lf" bag record --overwrite -o "$recorded" "${topics[@]}" >"$logs/record.log" 2>&1 &
recorder=$!
pids+=($recorder)

# each node announces itself on /lightfast/ready once it can take data: the sun update node once its lighting map
# is loaded (only then can it use the clock's preroll), the others once their kernels are compiled or loaded from
# numba's cache (on a fresh clone that takes a minute; the player's wait for subscribers does not cover it: the
# tracker alone subscribes to every topic it plays). A node that dies while starting fails the wait at once.
"$lf" wait-ready sun_update_node daylight_relight_node rgbd_tracker_node --timeout 300 \
  --pid "${pids[0]}" --pid "${pids[1]}" --pid "${pids[2]}" || { echo "the nodes did not start: see $logs" >&2; exit 1; }
# the clock runs $preroll s before the first frame: time for the first sun update epoch to stream in
names=(sun_update_node daylight_relight_node rgbd_tracker_node recorder)
cpu_before=()
for play in $(seq "$plays"); do
  echo "== playing $seq_dir/bag at rate $rate with /clock ($preroll s preroll)${play_args[*]:+ ${play_args[*]}} (play $play of $plays)"
  # /clock at 20 Hz between frames (and before each frame): every node on sim time takes each clock message
  "$lf" -v bag play "$seq_dir/bag" --rate "$rate" --clock 20 --preroll "$preroll" --wait-for-subscribers 120 \
    --topics /camera/color/image_raw /camera/color/camera_info /camera/depth/image_raw "${play_args[@]}" \
    >"$logs/player-$play.log" 2>&1 &
  player=$!
  pids+=($player)
  if [ "$play" = 1 ]; then
    # each process's CPU time from the first frame on (the player waits for its subscribers, then runs the preroll;
    # it reports its own CPU time from the first frame on)
    for _ in $(seq 3000); do
      grep -q "playing from bag time" "$logs/player-1.log" 2>/dev/null || ! kill -0 "$player" 2>/dev/null && break
      sleep 0.05
    done
    for pid in "${pids[@]:0:4}"; do cpu_before+=("$(cpu_seconds "$pid")"); done
  fi
  wait "$player" || { echo "bag play failed: see $logs/player-$play.log" >&2; exit 1; }
done
sleep 2  # the last frames' poses
cpu_line="CPU seconds from the first frame on:"
for i in "${!names[@]}"; do
  cpu_line+=" ${names[$i]} $(awk -v a="${cpu_before[$i]}" -v b="$(cpu_seconds "${pids[$i]}")" 'BEGIN {printf "%.1f", b - a}'),"
done
cpu_line+=" player $(sed -n 's/.*, \([0-9.]*\) s CPU.*/\1/p' "$logs/player-1.log" | tail -1)"

kill -INT "$recorder"
wait "$recorder" || true
echo "== result ($mode)"
"$lf" eval recording "$recorded" --truth "$seq_dir/bag"
echo "$cpu_line"
