# Process handling shared by the demo scripts (sourced, not run). Every background process a demo starts goes into
# `pids`; on exit, normal or Ctrl-C, all of them get SIGINT (ROS nodes shut down cleanly on it), those left after
# 10 s SIGTERM (a process still starting up may not listen to SIGINT yet: `cmd &` in a script starts it with SIGINT
# ignored until rclpy or the lightfast CLI installs a handler), those left 10 s later SIGKILL, and the script waits
# until they are gone, so that no process outlives its demo.
pids=()
running() {  # running PID...: those of them still running as background jobs of this shell. Bash's job table, not
  local pid live  # `kill -0`: pids are reused (pid_max is 32768 here), and a reused one is not ours to signal
  live=" $(jobs -rp | tr '\n' ' ') "
  for pid in "$@"; do [[ $live == *" $pid "* ]] && echo "$pid"; done
  return 0
}
stop() {  # stop PID: SIGINT, then wait up to 20 s, then SIGKILL
  local pid=$1
  kill -INT "$pid" 2>/dev/null || return 0
  timeout 20 tail --pid="$pid" -f /dev/null 2>/dev/null || kill -KILL "$pid" 2>/dev/null || true
}
cleanup() {  # SIGINT, SIGTERM after 10 s, SIGKILL 10 s later; returns only once every process is gone
  local sig left
  trap '' INT TERM  # a second Ctrl-C must not cut the cleanup short and leave processes behind
  for sig in INT TERM KILL; do
    left=$(running "${pids[@]}")
    [[ -z $left ]] && return 0
    [[ $sig == INT ]] || echo "still running, sending SIG$sig:" $left >&2
    kill "-$sig" $left 2>/dev/null || true
    for _ in $(seq 100); do [[ -z $(running "${pids[@]}") ]] && return 0; sleep 0.1; done
  done
  while [[ -n $(running "${pids[@]}") ]]; do sleep 0.1; done  # SIGKILL cannot be refused: they go
}
trap cleanup EXIT
trap 'echo "interrupted"; exit 130' INT TERM
cpu_seconds() {  # cpu_seconds PID: user + system CPU seconds the process has used so far (0 if it is gone)
  local stat
  stat=$(cat "/proc/$1/stat" 2>/dev/null) || { echo 0; return; }
  stat=${stat##*) }  # the fields after "pid (comm) "; utime and stime are the 12th and 13th of them
  awk -v hz="$(getconf CLK_TCK)" '{printf "%.2f", ($12 + $13) / hz}' <<<"$stat"
}
