"""Writes the benchmark log (see plant.py) as CSV: header `t,u,y`, full double precision.

Usage: python3 bench/peers/gen_data.py OUT.csv [SEED]

SEED (a non-negative integer) selects another realisation of the random input and output noise;
without it the log is the reference log of results.md (plant.SEED).
"""
import sys

import numpy as np

import plant


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit("usage: gen_data.py OUT.csv [SEED]")
    out = sys.argv[1]
    seed = plant.SEED
    if len(sys.argv) == 3:
        try:
            seed = int(sys.argv[2])
        except ValueError:
            sys.exit("gen_data.py: SEED must be a non-negative integer, got %r" % sys.argv[2])
        if seed < 0:
            sys.exit("gen_data.py: SEED must be a non-negative integer, got %d" % seed)
    u, y = plant.make_log(seed)
    t = np.arange(plant.N) * plant.TS
    with open(out, "w") as fh:
        fh.write("t,u,y\n")
        for row in zip(t, u, y):
            fh.write("%.17g,%.17g,%.17g\n" % row)
    print("wrote %s (%d samples, seed %d)" % (out, plant.N, seed), file=sys.stderr)


if __name__ == "__main__":
    main()
