#!/usr/bin/env python3
"""Generates showroom.gltf: a small glTF 2.0 scene written for Prism.

It exercises a node hierarchy with scale and rotation, flat and smooth
normals, metallic-roughness materials (with KHR_materials_specular,
KHR_materials_transmission, KHR_materials_ior and
KHR_materials_emissive_strength), KHR_lights_punctual and a camera.
Run it from this directory: python3 make_showroom.py
"""
import base64, json, math, struct

buf = bytearray()
views, accessors, meshes = [], [], []

def add(data, fmt, count, typ, target, minmax=None):
    while len(buf) % 4:
        buf.append(0)
    off = len(buf)
    buf.extend(struct.pack("<" + fmt * (len(data)), *data))
    views.append({"buffer": 0, "byteOffset": off, "byteLength": len(buf) - off, "target": target})
    acc = {"bufferView": len(views) - 1, "componentType": 5126 if fmt == "f" else 5125,
           "count": count, "type": typ}
    if minmax:
        acc["min"], acc["max"] = minmax
    accessors.append(acc)
    return len(accessors) - 1

def mesh(name, pos, nrm, uv, idx, material):
    flat = [c for p in pos for c in p]
    mn = [min(p[i] for p in pos) for i in range(3)]
    mx = [max(p[i] for p in pos) for i in range(3)]
    a_pos = add(flat, "f", len(pos), "VEC3", 34962, (mn, mx))
    a_nrm = add([c for n in nrm for c in n], "f", len(nrm), "VEC3", 34962)
    a_uv = add([c for t in uv for c in t], "f", len(uv), "VEC2", 34962)
    a_idx = add([i for t in idx for i in t], "I", len(idx) * 3, "SCALAR", 34963)
    meshes.append({"name": name, "primitives": [{"attributes": {"POSITION": a_pos, "NORMAL": a_nrm, "TEXCOORD_0": a_uv},
                                                 "indices": a_idx, "material": material}]})
    return len(meshes) - 1

def quad(size):
    s = size / 2
    pos = [(-s, 0, -s), (s, 0, -s), (s, 0, s), (-s, 0, s)]
    return pos, [(0, 1, 0)] * 4, [(0, 0), (1, 0), (1, 1), (0, 1)], [(0, 2, 1), (0, 3, 2)]

def cube():
    pos, nrm, uv, idx = [], [], [], []
    for axis in range(3):
        for sign in (-1, 1):
            n = [0, 0, 0]; n[axis] = sign
            u = [0, 0, 0]; u[(axis + 1) % 3] = 1
            v = [0, 0, 0]; v[(axis + 2) % 3] = 1
            base = len(pos)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                pos.append(tuple(0.5 * (n[i] + a * u[i] + b * v[i]) for i in range(3)))
                nrm.append(tuple(n)); uv.append(((a + 1) / 2, (b + 1) / 2))
            t = [(base, base + 1, base + 2), (base, base + 2, base + 3)]
            if sign < 0:
                t = [(x, z, y) for x, y, z in t]
            idx += t
    return pos, nrm, uv, idx

def sphere(r, seg=48, rings=24):
    pos, nrm, uv, idx = [], [], [], []
    for j in range(rings + 1):
        th = math.pi * j / rings
        for i in range(seg + 1):
            ph = 2 * math.pi * i / seg
            n = (math.sin(th) * math.cos(ph), math.cos(th), math.sin(th) * math.sin(ph))
            pos.append(tuple(r * c for c in n)); nrm.append(n); uv.append((i / seg, j / rings))
    for j in range(rings):
        for i in range(seg):
            a = j * (seg + 1) + i; b = a + seg + 1
            if j > 0: idx.append((a, a + 1, b))
            if j < rings - 1: idx.append((a + 1, b + 1, b))
    return pos, nrm, uv, idx

materials = [
    {"name": "floor", "pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.6, 0.62, 1], "metallicFactor": 0, "roughnessFactor": 1},
     "extensions": {"KHR_materials_specular": {"specularFactor": 0}}},
    {"name": "red plastic", "pbrMetallicRoughness": {"baseColorFactor": [0.7, 0.08, 0.05, 1], "metallicFactor": 0, "roughnessFactor": 0.35}},
    {"name": "gold mirror", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.77, 0.34, 1], "metallicFactor": 1, "roughnessFactor": 0}},
    {"name": "glass", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0, "roughnessFactor": 0},
     "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_ior": {"ior": 1.5}}},
    {"name": "lamp", "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0, "roughnessFactor": 1},
     "emissiveFactor": [1, 0.8, 0.5], "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4}}},
]
m_floor = mesh("floor", *quad(12), 0)
m_cube = mesh("cube", *cube(), 1)
m_gold = mesh("gold sphere", *sphere(0.7), 2)
m_glass = mesh("glass sphere", *sphere(0.55), 3)
m_lamp = mesh("lamp", *quad(0.8), 4)

def rot_y(deg):
    a = math.radians(deg) / 2
    return [0, math.sin(a), 0, math.cos(a)]

def look_rotation(eye, target):
    # Quaternion turning local -Z towards target with +Y up.
    f = [t - e for t, e in zip(target, eye)]; l = math.sqrt(sum(c * c for c in f)); f = [c / l for c in f]
    z = [-c for c in f]
    x = [z[2], 0, -z[0]]; lx = math.sqrt(sum(c * c for c in x)); x = [c / lx for c in x]
    y = [z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]]
    m = [[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]]
    tr = m[0][0] + m[1][1] + m[2][2]
    w = math.sqrt(max(0, 1 + tr)) / 2
    return [(m[2][1] - m[1][2]) / (4 * w), (m[0][2] - m[2][0]) / (4 * w), (m[1][0] - m[0][1]) / (4 * w), w]

eye, target = [0.0, 1.8, 5.5], [0.0, 0.7, 0.0]
nodes = [
    {"name": "floor", "mesh": m_floor},
    {"name": "display", "translation": [0, 0, 0], "scale": [1.2, 1.2, 1.2], "children": [2, 3, 4]},
    {"name": "cube", "mesh": m_cube, "translation": [-1.3, 0.5, -0.3], "rotation": rot_y(30)},
    {"name": "gold", "mesh": m_gold, "translation": [0.2, 0.7, -0.9]},
    {"name": "glass", "mesh": m_glass, "translation": [1.1, 0.55, 0.8]},
    {"name": "lamp", "mesh": m_lamp, "translation": [0, 3.2, 0], "rotation": [1, 0, 0, 0]},
    {"name": "key light", "translation": [3, 4.5, 3], "extensions": {"KHR_lights_punctual": {"light": 0}}},
    {"name": "sun", "rotation": [-0.3535534, 0.3535534, 0.1464466, 0.8535534], "extensions": {"KHR_lights_punctual": {"light": 1}}},
    {"name": "spot", "translation": [-3, 4, 2], "rotation": look_rotation([-3, 4, 2], [-1.5, 0, -0.3]), "extensions": {"KHR_lights_punctual": {"light": 2}}},
    {"name": "camera", "translation": eye, "rotation": look_rotation(eye, target), "camera": 0},
    {"name": "top camera", "translation": [0, 7, 0.01], "rotation": look_rotation([0, 7, 0.01], [0, 0, 0]), "camera": 1},
]
doc = {
    "asset": {"version": "2.0", "generator": "Prism make_showroom.py"},
    "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_specular", "KHR_materials_transmission",
                       "KHR_materials_ior", "KHR_materials_emissive_strength"],
    "extensions": {"KHR_lights_punctual": {"lights": [
        {"name": "key", "type": "point", "color": [1, 0.95, 0.9], "intensity": 120},
        {"name": "sun", "type": "directional", "color": [0.8, 0.9, 1.0], "intensity": 1.5},
        {"name": "spot", "type": "spot", "color": [1, 1, 1], "intensity": 150,
         "spot": {"innerConeAngle": 0.25, "outerConeAngle": 0.45}},
    ]}},
    "scene": 0,
    "scenes": [{"name": "showroom", "nodes": [0, 1, 5, 6, 7, 8, 9, 10]}],
    "nodes": nodes,
    "meshes": meshes,
    "materials": materials,
    "cameras": [{"type": "perspective", "perspective": {"yfov": 0.7, "znear": 0.05, "aspectRatio": 1.5}},
                {"type": "perspective", "perspective": {"yfov": 0.9, "znear": 0.05}}],
    "accessors": accessors,
    "bufferViews": views,
    "buffers": [{"byteLength": len(buf), "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(buf)).decode()}],
}
with open("showroom.gltf", "w") as f:
    json.dump(doc, f, indent=1)
print("wrote showroom.gltf:", sum(len(m["primitives"]) for m in meshes), "meshes")
