# Process handling shared by the demo scripts (sourced, not run). Every background process a demo starts goes into
# `pids`; on exit, normal or Ctrl-C, all of them get SIGINT (ROS nodes shut down cleanly on it), those left after
# 10 s SIGTERM (a process still starting up may not listen to SIGINT yet: `cmd &` in a script starts it with SIGINT
# ignored until rclpy or the lightfast CLI installs a handler), those left 10 s later SIGKILL, so that no process
# outlives its demo.
pids=()
alive() {  # alive PID...: whether any of them still runs
  local pid
  for pid in "$@"; do kill -0 "$pid" 2>/dev/null && return 0; done
  return 1
}
stop() {  # stop PID: SIGINT, then wait up to 20 s, then SIGKILL
  local pid=$1
  kill -INT "$pid" 2>/dev/null || return 0
  timeout 20 tail --pid="$pid" -f /dev/null 2>/dev/null || kill -KILL "$pid" 2>/dev/null || true
}
cleanup() {
  local sig pid
  for sig in INT TERM; do
    for pid in "${pids[@]}"; do kill "-$sig" "$pid" 2>/dev/null || true; done
    for _ in $(seq 100); do alive "${pids[@]}" || return 0; sleep 0.1; done
  done
  for pid in "${pids[@]}"; do kill -KILL "$pid" 2>/dev/null || true; done
}
trap cleanup EXIT
trap 'echo "interrupted"; exit 130' INT TERM
cpu_seconds() {  # cpu_seconds PID: user + system CPU seconds the process has used so far (0 if it is gone)
  local stat
  stat=$(cat "/proc/$1/stat" 2>/dev/null) || { echo 0; return; }
  stat=${stat##*) }  # the fields after "pid (comm) "; utime and stime are the 12th and 13th of them
  awk -v hz="$(getconf CLK_TCK)" '{printf "%.2f", ($12 + $13) / hz}' <<<"$stat"
}
