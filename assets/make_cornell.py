#!/usr/bin/env python3
"""Writes assets/cornell.toml: the Cornell box (after the measured data
published by the Cornell Program of Computer Graphics), scaled by 0.01, as
convex polygons with inward-facing walls, outward-facing blocks and a
downward-facing area light. Run from the repository root."""

S = 0.01  # the published figures are millimetres; the scene uses 0.01 of them

def poly(name, verts, material, toward=None, away=None):
    """Orders `verts` so the polygon's normal points toward `toward` (or
    away from `away`), and returns the TOML object."""
    a, b, c = verts[0], verts[1], verts[2]
    u = [b[i] - a[i] for i in range(3)]
    v = [c[i] - a[i] for i in range(3)]
    n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
    centre = [sum(p[i] for p in verts) / len(verts) for i in range(3)]
    if toward is not None:
        d = [toward[i] - centre[i] for i in range(3)]
    else:
        d = [centre[i] - away[i] for i in range(3)]
    if sum(n[i] * d[i] for i in range(3)) < 0:
        verts = list(reversed(verts))
    vs = ", ".join("[%.4f, %.4f, %.4f]" % tuple(x * S for x in p) for p in verts)
    return f'[[objects]]\nname = "{name}"\nshape = {{ type = "polygon", vertices = [{vs}] }}\nmaterial = "{material}"\n'

inside = (278, 274, 280)
out = ["""# The Cornell box, after the measured geometry published by the Cornell
# Program of Computer Graphics: white floor, ceiling and back wall, a red
# left wall, a green right wall, two white blocks, and a square area light
# in the ceiling. Written by assets/make_cornell.py; lengths are the
# published millimetre figures times 0.01 (the box is 5.5 units across).
#
# The only light is the emissive ceiling panel, so this scene needs
# `--transport path` (its default here): the Whitted transport sees the
# panel but nothing it lights.

[settings]
width = 256
height = 256
spp = 16
max_depth = 8
transport = "path"
russian_roulette = 3

[camera]
look_from = [2.78, 2.73, -8.0]
look_at = [2.78, 2.73, 0.0]
vfov = 39.3

[materials.white]
color = [0.725, 0.71, 0.68]

[materials.red]
color = [0.63, 0.065, 0.05]

[materials.green]
color = [0.14, 0.45, 0.091]

[materials.light]
color = 0.78
emission = [17.0, 12.0, 4.0]
"""]
# The measured walls are a few millimetres out of square (and so not quite
# planar); this box squares them: X 0..556, Y 0..548.8, Z 0..559.2.
X, Y, Z = 556, 548.8, 559.2
out.append(poly("floor", [(X, 0, 0), (0, 0, 0), (0, 0, Z), (X, 0, Z)], "white", toward=inside))
# The ceiling has a hole where the light is, and the light fills it flush:
# a light hung just below a closed ceiling would light the thin gap above
# it (emission is two-sided), a trap that paths reach only at grazing
# angles and that shows up as fireflies.
LX0, LX1, LZ0, LZ1 = 213, 343, 227, 332
for k, (x0, x1, z0, z1) in enumerate([(0, X, 0, LZ0), (0, X, LZ1, Z), (0, LX0, LZ0, LZ1), (LX1, X, LZ0, LZ1)]):
    out.append(poly(f"ceiling {k}", [(x0, Y, z0), (x1, Y, z0), (x1, Y, z1), (x0, Y, z1)], "white", toward=inside))
out.append(poly("back wall", [(X, 0, Z), (0, 0, Z), (0, Y, Z), (X, Y, Z)], "white", toward=inside))
out.append(poly("right wall (green)", [(0, 0, Z), (0, 0, 0), (0, Y, 0), (0, Y, Z)], "green", toward=inside))
out.append(poly("left wall (red)", [(X, 0, 0), (X, 0, Z), (X, Y, Z), (X, Y, 0)], "red", toward=inside))
out.append(poly("light", [(LX1, Y, LZ0), (LX1, Y, LZ1), (LX0, Y, LZ1), (LX0, Y, LZ0)], "light", toward=(278, 0, 280)))

def block(name, top, height):
    c = [sum(p[i] for p in top) / 4 for i in (0, 1)]
    centre = (c[0], height / 2, c[1])
    objs = [poly(name + " top", [(x, height, z) for (x, z) in top], "white", away=centre)]
    for k in range(4):
        (x0, z0), (x1, z1) = top[k], top[(k + 1) % 4]
        objs.append(poly(f"{name} side {k}", [(x0, 0, z0), (x1, 0, z1), (x1, height, z1), (x0, height, z0)], "white", away=centre))
    return objs

out += block("short block", [(130, 65), (82, 225), (240, 272), (290, 114)], 165)
out += block("tall block", [(423, 247), (265, 296), (314, 456), (472, 406)], 330)
open("assets/cornell.toml", "w").write("\n".join(out))
