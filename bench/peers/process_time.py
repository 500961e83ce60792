"""Whole-process time of `ferrosid identify` on the peer log (issue 16, item 3).

Usage: python3 process_time.py FERROSID_BINARY LOG OUT.json REPEATS

Runs `FERROSID_BINARY identify LOG --input u --output y --json` (automatic order, i = 20)
REPEATS times (after one untimed warm-up run that brings the file into the page cache) and
writes the best and median wall time from process start to exit, the best and median CPU time
(user + system, from the kernel's accounting of the child) and the system load average at the
start, plus the model's order, to OUT.json. This is what a user waits for: reading the CSV, preprocessing, N4SID, the continuous
equivalent, validation and writing the JSON, unlike the peers' in-tool kernel times.
"""
import json
import os
import statistics
import subprocess
import sys
import time


def main():
    exe, log, out, repeats = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
    cmd = [exe, "identify", log, "--input", "u", "--output", "y", "--json"]
    first = subprocess.run(cmd, capture_output=True, check=False)
    if first.returncode not in (0, 1):
        sys.stderr.write(first.stderr.decode(errors="replace"))
        raise SystemExit("process_time: `%s` failed with exit status %d"
                         % (" ".join(cmd), first.returncode))
    report = json.loads(first.stdout)
    load = os.getloadavg()[0]
    times, cpu = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        child = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        _, _, usage = os.wait4(child.pid, 0)
        times.append(time.perf_counter() - t0)
        cpu.append(usage.ru_utime + usage.ru_stime)
    with open(out, "w") as f:
        json.dump({
            "command": " ".join(cmd),
            "identify_process_best_seconds": min(times),
            "identify_process_median_seconds": statistics.median(times),
            "identify_process_cpu_best_seconds": min(cpu),
            "identify_process_cpu_median_seconds": statistics.median(cpu),
            "load_average_1min": load,
            "repeats": repeats,
            "order": len(report["poles"]),
        }, f, indent=1)
    sys.stderr.write("identify process: wall best %.1f ms median %.1f ms, CPU best %.1f ms median "
                     "%.1f ms (%d runs, load average %.2f)\n"
                     % (1e3 * min(times), 1e3 * statistics.median(times), 1e3 * min(cpu),
                        1e3 * statistics.median(cpu), repeats, load))


if __name__ == "__main__":
    main()
