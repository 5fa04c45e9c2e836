#!/usr/bin/env python3
"""Writes cornell.gltf and spheres.gltf (each with its .bin): the two scenes
of the equal-error comparison with Mitsuba 3 (README, "Path tracing against
Mitsuba 3"), in the subset of glTF that ../shared/peers/mitsuba_render.py
converts exactly: Lambertian materials (metallic 0, roughness 1,
KHR_materials_specular 0), a perfect mirror (metallic 1, roughness 0),
smooth glass (KHR_materials_transmission 1, roughness 0, KHR_materials_ior),
one-sided emission (KHR_materials_emissive_strength) and a perspective
camera.

* cornell.gltf: the Cornell box of ../cornell.toml (the same polygons,
  triangulated, and the same materials and camera), for a 320x240 image.
* spheres.gltf: a mirror, a glass and a diffuse sphere (UV spheres of
  9,216 triangles each) on a diffuse floor before a diffuse wall, lit by a
  square emissive panel (no point light: Prism renders glTF roughness 0 as
  GGX of alpha 0.001, which shows a point light's tiny highlight in the
  mirror, where Mitsuba's smooth conductor, a true delta, cannot).

Run from this directory: python3 make_peer_scenes.py
"""
import json
import math
import struct
import tomllib


class Builder:
    def __init__(self, name):
        self.name = name
        self.buf = bytearray()
        self.views, self.accessors, self.meshes, self.nodes = [], [], [], []
        self.materials = []

    def add(self, values, fmt, count, typ, target, minmax=None):
        while len(self.buf) % 4:
            self.buf.append(0)
        off = len(self.buf)
        self.buf.extend(struct.pack("<%d%s" % (len(values), fmt), *values))
        self.views.append({"buffer": 0, "byteOffset": off, "byteLength": len(self.buf) - off, "target": target})
        acc = {"bufferView": len(self.views) - 1, "componentType": 5126 if fmt == "f" else 5125,
               "count": count, "type": typ}
        if minmax:
            acc["min"], acc["max"] = minmax
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def mesh(self, name, pos, nrm, idx, material):
        mn = [min(p[i] for p in pos) for i in range(3)]
        mx = [max(p[i] for p in pos) for i in range(3)]
        a_pos = self.add([c for p in pos for c in p], "f", len(pos), "VEC3", 34962, (mn, mx))
        a_nrm = self.add([c for n in nrm for c in n], "f", len(nrm), "VEC3", 34962)
        a_idx = self.add([i for t in idx for i in t], "I", len(idx) * 3, "SCALAR", 34963)
        self.meshes.append({"name": name, "primitives": [
            {"attributes": {"POSITION": a_pos, "NORMAL": a_nrm}, "indices": a_idx, "material": material}]})
        return len(self.meshes) - 1

    def material(self, m):
        self.materials.append(m)
        return len(self.materials) - 1

    def node(self, n):
        self.nodes.append(n)
        return len(self.nodes) - 1

    def write(self, camera, lights=()):
        ext = ["KHR_materials_specular", "KHR_materials_transmission", "KHR_materials_ior",
               "KHR_materials_emissive_strength"]
        doc = {
            "asset": {"version": "2.0", "generator": "Prism assets/gltf/make_peer_scenes.py"},
            "extensionsUsed": ext + (["KHR_lights_punctual"] if lights else []),
            "scene": 0,
            "scenes": [{"name": self.name, "nodes": list(range(len(self.nodes)))}],
            "nodes": self.nodes,
            "meshes": self.meshes,
            "materials": self.materials,
            "cameras": [camera],
            "accessors": self.accessors,
            "bufferViews": self.views,
            "buffers": [{"uri": self.name + ".bin", "byteLength": len(self.buf)}],
        }
        if lights:
            doc["extensions"] = {"KHR_lights_punctual": {"lights": list(lights)}}
        with open(self.name + ".bin", "wb") as f:
            f.write(self.buf)
        with open(self.name + ".gltf", "w") as f:
            json.dump(doc, f, indent=1)


def lambert(name, rgb):
    return {"name": name, "pbrMetallicRoughness": {"baseColorFactor": list(rgb) + [1], "metallicFactor": 0,
                                                   "roughnessFactor": 1},
            "extensions": {"KHR_materials_specular": {"specularFactor": 0}}}


def emitter(name, radiance):
    peak = max(radiance)
    return {"name": name, "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0,
                                                   "roughnessFactor": 1},
            "extensions": {"KHR_materials_specular": {"specularFactor": 0},
                           "KHR_materials_emissive_strength": {"emissiveStrength": peak}},
            "emissiveFactor": [c / peak for c in radiance]}


def look_rotation(eye, target):
    """Quaternion turning local -Z towards `target`, +Y up."""
    f = [t - e for t, e in zip(target, eye)]
    l = math.sqrt(sum(c * c for c in f))
    z = [-c / l for c in f]
    x = [z[2], 0.0, -z[0]]
    lx = math.sqrt(sum(c * c for c in x))
    x = [c / lx for c in x]
    y = [z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]]
    m = [[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]]
    # The rotation matrix's quaternion from its largest component (no
    # division by a small one: a camera looking along +Z has w = 0).
    tr = m[0][0] + m[1][1] + m[2][2]
    if tr > 0:
        k = 2 * math.sqrt(1 + tr)
        return [(m[2][1] - m[1][2]) / k, (m[0][2] - m[2][0]) / k, (m[1][0] - m[0][1]) / k, k / 4]
    i = max(range(3), key=lambda a: m[a][a])
    j, l = (i + 1) % 3, (i + 2) % 3
    k = 2 * math.sqrt(max(0.0, 1 + m[i][i] - m[j][j] - m[l][l]))
    q = [0.0] * 4
    q[i] = k / 4
    q[j] = (m[j][i] + m[i][j]) / k
    q[l] = (m[l][i] + m[i][l]) / k
    q[3] = (m[l][j] - m[j][l]) / k
    return q


def polygon(verts):
    """Fan triangles of a convex polygon with its face normal."""
    a, b, c = verts[0], verts[1], verts[2]
    u = [b[i] - a[i] for i in range(3)]
    v = [c[i] - a[i] for i in range(3)]
    n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
    ln = math.sqrt(sum(x * x for x in n))
    n = [x / ln for x in n]
    return verts, [n] * len(verts), [(0, k, k + 1) for k in range(1, len(verts) - 1)]


def sphere(r, seg=96, rings=48):
    pos, nrm, idx = [], [], []
    for j in range(rings + 1):
        th = math.pi * j / rings
        for i in range(seg + 1):
            ph = 2 * math.pi * i / seg
            n = (math.sin(th) * math.cos(ph), math.cos(th), -math.sin(th) * math.sin(ph))
            pos.append(tuple(r * c for c in n))
            nrm.append(n)
    for j in range(rings):
        for i in range(seg):
            a = j * (seg + 1) + i
            b = a + seg + 1
            if j > 0:
                idx.append((a, b, a + 1))
            if j < rings - 1:
                idx.append((a + 1, b, b + 1))
    return pos, nrm, idx


def camera(eye, target, yfov_deg, aspect):
    return ({"type": "perspective", "perspective": {"yfov": math.radians(yfov_deg), "znear": 0.01,
                                                   "aspectRatio": aspect}},
            {"name": "camera", "translation": list(eye), "rotation": look_rotation(eye, target), "camera": 0})


def cornell():
    with open("../cornell.toml", "rb") as f:
        desc = tomllib.load(f)
    g = Builder("cornell")
    mats = {}
    for name, m in desc["materials"].items():
        col = m["color"] if isinstance(m["color"], list) else [m["color"]] * 3
        if "emission" in m:
            mats[name] = g.material(emitter(name, m["emission"]))
        else:
            mats[name] = g.material(lambert(name, col))
    for obj in desc["objects"]:
        pos, nrm, idx = polygon([tuple(v) for v in obj["shape"]["vertices"]])
        g.node({"name": obj["name"], "mesh": g.mesh(obj["name"], pos, nrm, idx, mats[obj["material"]])})
    cam, node = camera(desc["camera"]["look_from"], desc["camera"]["look_at"], desc["camera"]["vfov"], 4 / 3)
    g.node(node)
    g.write(cam)


def spheres():
    g = Builder("spheres")
    white = g.material(lambert("white", (0.75, 0.75, 0.72)))
    wall = g.material(lambert("wall", (0.55, 0.6, 0.7)))
    diffuse = g.material(lambert("red", (0.7, 0.15, 0.1)))
    mirror = g.material({"name": "mirror", "pbrMetallicRoughness": {"baseColorFactor": [0.95, 0.95, 0.95, 1],
                                                                    "metallicFactor": 1, "roughnessFactor": 0}})
    glass = g.material({"name": "glass", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1],
                                                                  "metallicFactor": 0, "roughnessFactor": 0},
                        "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1},
                                       "KHR_materials_ior": {"ior": 1.5}}})
    lamp = g.material(emitter("panel", (12.0, 11.0, 9.0)))
    s = 6.0
    pos, nrm, idx = polygon([(-s, 0, s), (s, 0, s), (s, 0, -s), (-s, 0, -s)])
    g.node({"name": "floor", "mesh": g.mesh("floor", pos, nrm, idx, white)})
    pos, nrm, idx = polygon([(-s, 0, -3), (s, 0, -3), (s, 5, -3), (-s, 5, -3)])
    g.node({"name": "wall", "mesh": g.mesh("wall", pos, nrm, idx, wall)})
    for name, mat, x, r in (("mirror sphere", mirror, -1.6, 0.8), ("glass sphere", glass, 0.0, 0.8),
                            ("diffuse sphere", diffuse, 1.6, 0.8)):
        pos, nrm, idx = sphere(r)
        g.node({"name": name, "mesh": g.mesh(name, pos, nrm, idx, mat), "translation": [x, r, 0.0]})
    # The panel faces down (its normal -Y): nothing above it sees its back.
    h = 0.75
    pos, nrm, idx = polygon([(-h, 4.0, -h), (h, 4.0, -h), (h, 4.0, h), (-h, 4.0, h)])
    g.node({"name": "panel", "mesh": g.mesh("panel", pos, nrm, idx, lamp)})
    cam, node = camera((0.0, 1.6, 6.0), (0.0, 0.8, 0.0), 40.0, 4 / 3)
    g.node(node)
    g.write(cam)


if __name__ == "__main__":
    cornell()
    spheres()
