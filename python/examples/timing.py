"""Per-log time through Python vs the CLI, and fleet throughput on Dask for 1 and 2 workers
(the figures of docs/benchmarks.md "Python"). Run from the repository root after
scripts/python-setup.sh --no-test and `cargo build -p ferrosid`:

    target/python-venv/bin/python python/examples/timing.py            # everything
    target/python-venv/bin/python python/examples/timing.py --quick    # identify and frf only
    target/python-venv/bin/python python/examples/timing.py --stages   # audit/fit_wm/tune_pid/gap
"""
import os
import statistics
import subprocess
import sys
import time

import numpy as np

import ferrosid

CLI = os.environ.get("FERROSID_CLI", "target/debug/ferrosid")
LOW = "examples/data/two_mass_low.csv"
HIGH = "examples/data/two_mass_high.csv"
VAL = "examples/data/two_mass_validate.csv"
REPEAT = 5


def best(f, n=REPEAT):
    ts = []
    for _ in range(n):
        t0 = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t0)
    return min(ts), statistics.median(ts)


def cli(*args):
    subprocess.run([CLI, *args], check=False, capture_output=True)


def stages():
    """The pipeline's stages on arrays (the bundled example's three logs and settings); gap
    also through `ferrosid gap` on the model.json of the run (no CLI command for the others)."""
    run = ferrosid.run_pipeline("examples/pipeline.toml")
    os.makedirs("target", exist_ok=True)
    with open("target/timing-model.json", "w") as f:
        f.write(run.model_json())
    (_, u1, y1), (_, u2, y2), (_, u3, y3) = (
        np.loadtxt(p, delimiter=",", skiprows=1, unpack=True) for p in (LOW, HIGH, VAL))
    m, etfe = run.model, dict(nperseg=500, coherence_gate=0.85)
    runs = dict(low=(u1, y1, 0.05), high=(u2, y2, 0.15))
    wm = ferrosid.fit_wm(m, **runs, validation=(u3, y3), fs=1000.0, **etfe)
    control = dict(crossover_hz=8.0, rolloff_ratio=4.0, ms_max=1.6, actuator_limit=0.3,
                   reference_amplitude=5.0)
    rows = [
        ("audit (two runs)", None,
         lambda: ferrosid.audit(**runs, fs=1000.0, crossover_hz=8.0, **etfe)),
        ("fit_wm (three logs)", None,
         lambda: ferrosid.fit_wm(m, **runs, validation=(u3, y3), fs=1000.0, **etfe)),
        ("tune_pid", None, lambda: ferrosid.tune_pid(m, wm, **control)),
        ("gap (two runs + validation)",
         lambda: cli("gap", "--sim", "target/timing-model.json", "--real", LOW, "--real", HIGH,
                     "--validate", VAL, "--json"),
         lambda: ferrosid.gap(m, low=(u1, y1), high=(u2, y2), validation=(u3, y3), fs=1000.0)),
    ]
    for name, c, p in rows:
        pb, pm = best(p)
        line = f"{name}: Python best {pb*1e3:.1f} ms (median {pm*1e3:.1f})"
        if c is not None:
            cb, cm = best(c)
            line += f", CLI best {cb*1e3:.1f} ms (median {cm*1e3:.1f})"
        print(line)


def main():
    if "--stages" in sys.argv:
        return stages()
    t, u, y = np.loadtxt(HIGH, delimiter=",", skiprows=1, unpack=True)
    rows = [
        (f"identify (one {u.size}-sample log)",
         lambda: cli("identify", HIGH, "--fs", "1000", "--json"),
         lambda: ferrosid.identify(u, y, fs=1000.0, name=HIGH)),
        ("frf (one log)",
         lambda: cli("frf", HIGH, "--fs", "1000", "--json"),
         lambda: ferrosid.frf(u, y, fs=1000.0, name=HIGH)),
        ("run examples/pipeline.toml",
         lambda: cli("run", "examples/pipeline.toml", "--out", "target/timing-out", "--json"),
         lambda: ferrosid.run_pipeline("examples/pipeline.toml").to_json()),
    ]
    for name, c, p in rows[:2] if "--quick" in sys.argv else rows:
        (cb, cm), (pb, pm) = best(c), best(p)
        print(f"{name}: CLI best {cb*1e3:.1f} ms (median {cm*1e3:.1f}), "
              f"Python best {pb*1e3:.1f} ms (median {pm*1e3:.1f})")
    if "--quick" in sys.argv:
        rows = []
    for jobs in (1, 2):
        b, m = best(lambda: cli("fleet", "examples/fleet", "--jobs", str(jobs), "--out",
                                "target/timing-fleet", "--json"), 3)
        print(f"ferrosid fleet --jobs {jobs}: best {b:.2f} s = {6/b:.2f} units/s (median {m:.2f} s)")
    sys.path.insert(0, os.path.dirname(__file__))
    import dask_fleet
    from dask.distributed import Client, LocalCluster
    for workers in (1, 2):
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cl, Client(cl) as client:
            dask_fleet.run_fleet_on_dask("examples/fleet", client)  # warm the workers
            b, m = best(lambda: dask_fleet.run_fleet_on_dask("examples/fleet", client), 3)
        print(f"Dask LocalCluster {workers} worker(s): best {b:.2f} s = {6/b:.2f} units/s "
              f"(median {m:.2f} s)")


if __name__ == "__main__":
    main()
