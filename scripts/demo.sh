#!/usr/bin/env bash
# The main job, launch-free: set up, convert the real 7-Scenes frames into an MCAP bag (once), replay it live in
# one process while another records it, then print one summary line per stage (what was played; what arrived:
# counts, rates, drops). Ctrl-C stops every process this script started.
#
# Environment: LIGHTFAST_SHARED (default ../shared beside the checkout), LIGHTFAST_OUT (default ./out),
# ROS_DOMAIN_ID (default: a random id), RATE (playback rate, default 1 = real time; 0 = as fast as possible).
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bash "$root/scripts/setup.sh"
lf="$root/.venv/bin/lightfast"
shared=${LIGHTFAST_SHARED:-$root/../shared}
out=${LIGHTFAST_OUT:-$root/out}
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$(( (RANDOM % 200) + 20 ))}
rate=${RATE:-1}
mkdir -p "$out"

bag="$out/7scenes_redkitchen_300"
if [ ! -f "$bag/metadata.yaml" ]; then
  echo "== converting $shared/data/7scenes_redkitchen_300 to $bag"
  "$lf" data 7scenes "$shared/data/7scenes_redkitchen_300" "$bag"
fi

pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill -INT "$pid" 2>/dev/null || true; done
  for pid in "${pids[@]}"; do
    timeout 10 tail --pid="$pid" -f /dev/null 2>/dev/null || kill -KILL "$pid" 2>/dev/null || true
  done
}
trap cleanup EXIT
trap 'echo "interrupted"; exit 130' INT TERM

recorded="$out/demo-recording"
topics=(/camera/color/image_raw /camera/color/camera_info /camera/depth/image_raw /camera/depth/camera_info
        /ground_truth/pose)
echo "== recording ${#topics[@]} topics to $recorded (domain $ROS_DOMAIN_ID)"
"$lf" bag record --overwrite -o "$recorded" "${topics[@]}" &
pids+=($!)
recorder=$!

echo "== playing $bag at rate $rate"
"$lf" bag play "$bag" --rate "$rate" --wait-for-subscribers 20

kill -INT "$recorder"
wait "$recorder"
pids=()
echo "== summary"
"$lf" bag compare "$bag" "$recorded"
