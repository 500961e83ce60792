"""Writes the benchmark log (see plant.py) as CSV: header `t,u,y`, full double precision.

Usage: python3 bench/peers/gen_data.py OUT.csv
"""
import sys

import numpy as np

import plant


def main():
    out = sys.argv[1]
    u, y = plant.make_log()
    t = np.arange(plant.N) * plant.TS
    with open(out, "w") as fh:
        fh.write("t,u,y\n")
        for row in zip(t, u, y):
            fh.write("%.17g,%.17g,%.17g\n" % row)
    print("wrote %s (%d samples)" % (out, plant.N), file=sys.stderr)


if __name__ == "__main__":
    main()
