"""How busy a command's threads are: running, waiting for a core, or asleep.

    python3 tools/speed/thread_busy.py COMMAND [ARGS...]

Runs COMMAND, samples its threads' /proc/PID/task/*/schedstat (nanoseconds on a core, and
waiting on a run queue) every 0.2 s, and prints for each thread on a core more than 5 % of the
wall time its shares of it. A thread that is rarely asleep keeps its core busy whenever the
scheduler lets it: on a shared machine "waiting" is the other work's share, not the command's
idling (docs/speed.md, "Pair lists"). Linux only.
"""

import glob
import subprocess
import sys
import time


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    start = time.perf_counter()
    child = subprocess.Popen(sys.argv[1:])
    last = {}  # schedstat path -> (ns running, ns waiting), the last sample before it ended
    while child.poll() is None:
        for path in glob.glob(f"/proc/{child.pid}/task/*/schedstat"):
            try:
                running, waiting, _ = open(path).read().split()
                last[path] = (int(running), int(waiting))
            except (OSError, ValueError):
                pass  # the thread ended between the listing and the read
        time.sleep(0.2)
    wall = time.perf_counter() - start
    busy = sorted((t for t in last.values() if t[0] > 0.05e9 * wall), reverse=True)
    print(f"wall {wall:.1f} s; threads on a core more than 5 % of it: {len(busy)}")
    for running, waiting in busy:
        run, wait = 100 * running / 1e9 / wall, 100 * waiting / 1e9 / wall
        print(f"  running {run:.0f} %, waiting for a core {wait:.0f} %, asleep {100 - run - wait:.0f} %")
    sys.exit(child.returncode)


if __name__ == "__main__":
    main()
