# Process handling shared by the demo scripts (sourced, not run). Every background process a demo starts goes into
# `pids`; on exit, normal or Ctrl-C, each gets SIGINT (ROS nodes shut down cleanly on it), then up to 20 s, then
# SIGKILL, so that no process outlives its demo.
pids=()
stop() {  # stop PID: SIGINT, then wait up to 20 s, then SIGKILL
  local pid=$1
  kill -INT "$pid" 2>/dev/null || return 0
  timeout 20 tail --pid="$pid" -f /dev/null 2>/dev/null || kill -KILL "$pid" 2>/dev/null || true
}
cleanup() {
  for pid in "${pids[@]}"; do kill -INT "$pid" 2>/dev/null || true; done
  for pid in "${pids[@]}"; do stop "$pid"; done
}
trap cleanup EXIT
trap 'echo "interrupted"; exit 130' INT TERM
