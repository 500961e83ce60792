"""A fleet on Dask: the pipeline on every unit of a fleet directory, one task per unit, the
results gathered into the same summary `ferrosid fleet --json` prints.

    python python/examples/dask_fleet.py examples/fleet                 # local cluster
    python python/examples/dask_fleet.py examples/fleet --workers 2
    python python/examples/dask_fleet.py /shared/line3 --scheduler tcp://head:8786

On a multi-node cluster nothing changes but the scheduler address: every worker needs the
ferrosid package and the fleet directory at the same path (a shared file system). Each task
is a pure function of the unit's files (`ferrosid.fleet_unit`); the tasks release the GIL, so
a worker's threads run units in parallel too. `--structure two-mass --known Kt=1` fits the
physical structure on every unit as `ferrosid fleet --structure ... --known ...` does.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Dict, Optional

import ferrosid


def run_fleet_on_dask(
    fleet_dir: str,
    client,
    template: Optional[str] = None,
    physical: Optional[Dict] = None,
) -> ferrosid.FleetSummary:
    """The fleet summary of `fleet_dir` computed on the Dask `client`'s workers."""
    fleet_dir = os.path.abspath(fleet_dir)
    template = os.path.abspath(template or os.path.join(fleet_dir, "pipeline.toml"))
    layout, serials = ferrosid.fleet_units(fleet_dir)
    futures = client.map(
        ferrosid.fleet_unit,
        [fleet_dir] * len(serials),
        [template] * len(serials),
        [layout] * len(serials),
        serials,
        [physical] * len(serials),
        pure=False,  # fresh task keys on every call: the files may have changed
    )
    units = client.gather(futures)
    return ferrosid.fleet_summary(template, layout, units)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", help="fleet directory (one subdirectory or file prefix per unit)")
    ap.add_argument("--pipeline", help="template (default DIR/pipeline.toml)")
    ap.add_argument("--scheduler", help="address of an existing Dask scheduler")
    ap.add_argument("--workers", type=int, default=2, help="local cluster workers (default 2)")
    ap.add_argument("--threads", type=int, default=1, help="threads per local worker")
    ap.add_argument("--structure", help="physical structure to fit on every unit")
    ap.add_argument("--known", action="append", default=[], help="NAME=VALUE, SI units")
    ap.add_argument("--json", action="store_true", help="print the summary JSON")
    a = ap.parse_args(argv)
    from dask.distributed import Client, LocalCluster

    physical = None
    if a.structure:
        known = {k: float(v) for k, v in (kv.split("=", 1) for kv in a.known)}
        physical = {"structure": a.structure, "known": known}
    if a.scheduler:
        client, cluster = Client(a.scheduler), None
    else:
        cluster = LocalCluster(n_workers=a.workers, threads_per_worker=a.threads,
                               processes=True, dashboard_address=None)
        client = Client(cluster)
    try:
        t0 = time.perf_counter()
        s = run_fleet_on_dask(a.dir, client, a.pipeline, physical)
        dt = time.perf_counter() - t0
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    if a.json:
        sys.stdout.write(s.to_json())
    else:
        d = s.to_dict()
        n = len(d["units"])
        print(f"{n} units in {dt:.2f} s ({n / dt:.2f} units/s): "
              f"{d['units_pass']} pass, {d['units_fail']} fail, {d['units_error']} error")
        for o in d["outliers"]:
            print(f"  outlier: {o['serial']} {o['parameter']} = {o['value']:.4g} "
                  f"(median {o['median']:.4g})")
    return 0 if s["units_fail"] == 0 and s["units_error"] == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
