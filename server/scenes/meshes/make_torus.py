#!/usr/bin/env python3
"""Writes torus.obj: a closed triangulated torus standing in the x-y plane (axis z).

Usage: python3 make_torus.py [OUT.obj]. The shipped torus.obj is this script's
output with the defaults below; rerun it after changing them.
"""
import math
import sys

MAJOR_RADIUS = 0.10  # centre of the tube to the axis [m]
MINOR_RADIUS = 0.035  # radius of the tube [m]
AROUND = 36  # segments around the axis
TUBE = 12  # segments around the tube
CENTRE = (0.0, 0.135, 0.0)  # the lowest point sits at y = 0


def main() -> None:
    out = sys.argv[1] if len(sys.argv) > 1 else "torus.obj"
    lines = [
        "# torus: major radius %g m, minor radius %g m, %d x %d quads split into triangles"
        % (MAJOR_RADIUS, MINOR_RADIUS, AROUND, TUBE),
        "# written by make_torus.py",
    ]
    for i in range(AROUND):
        u = 2.0 * math.pi * i / AROUND
        for j in range(TUBE):
            v = 2.0 * math.pi * j / TUBE
            rho = MAJOR_RADIUS + MINOR_RADIUS * math.cos(v)
            x = CENTRE[0] + rho * math.cos(u)
            y = CENTRE[1] + rho * math.sin(u)
            z = CENTRE[2] + MINOR_RADIUS * math.sin(v)
            lines.append("v %.9f %.9f %.9f" % (x, y, z))
    for i in range(AROUND):
        for j in range(TUBE):
            a = 1 + i * TUBE + j
            b = 1 + ((i + 1) % AROUND) * TUBE + j
            c = 1 + ((i + 1) % AROUND) * TUBE + (j + 1) % TUBE
            d = 1 + i * TUBE + (j + 1) % TUBE
            # Wound so that the normals point out of the tube.
            lines.append("f %d %d %d" % (a, b, c))
            lines.append("f %d %d %d" % (a, c, d))
    with open(out, "w", encoding="ascii") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
