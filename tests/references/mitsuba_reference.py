#!/usr/bin/env python3
"""Render a Prism scene file that includes a glTF model with Mitsuba 3, as a reference image.

The references in this folder (see README.md here) were made with this script: it reads the
small subset of Prism's TOML scene format that the reference scenes use, converts the glTF
model it includes, and renders the result with Mitsuba 3's path tracer. The glTF
metallic-roughness material is a Mitsuba BSDF written here in Python from appendix B of the
glTF 2.0 specification (GGX with alpha = roughness^2, height-correlated Smith visibility,
Schlick Fresnel on the half vector, `fresnel_mix` of a Lambertian base under the dielectric
layer with F0 = 0.04, the metal tinted by the base colour), independently of Prism's Rust
code, sampled by the classic distribution of normals (not Prism's visible normals) mixed
with cosine sampling.

  python3 -m venv ~/.cache/peers-venv && ~/.cache/peers-venv/bin/pip install mitsuba numpy openexr
  apt-get install -y libllvm19                       # Mitsuba's llvm_ad_rgb variant
  ~/.cache/peers-venv/bin/python tests/references/mitsuba_reference.py \
      tests/references/metal_rough_spheres.toml -o tests/references/metal_rough_spheres.exr --spp 4096

TOML subset read: [settings] width, height, max_depth; [camera] look_from, look_at, up, vfov;
[environment] color (uniform) and intensity; [[objects]] with a `polygon` shape whose
material has `emission` (one-sided here, facing where its vertices wind counter-clockwise;
the reference scenes place such lights so that nothing sees their back); [[gltf]] path,
translate, scale. glTF read: node hierarchies (TRS or matrix), EXT_mesh_gpu_instancing,
triangle primitives with POSITION, NORMAL, TEXCOORD_0 (float32), u8/u16/u32 indices,
pbrMetallicRoughness factors and textures (base colour in sRGB, metallic in blue and
roughness in green), normal textures (tangent space, glTF's green-up convention with
tangents from dP/du and handedness from dP/dv of the triangle) and the glTF default
material. Anything else is an error.

Prism's `max_depth` d (scattering events) is Mitsuba's `max_depth` d + 1 (Mitsuba counts the
camera segment). Writes a half-float linear RGB EXR and, beside it, a .json with the provenance
(Mitsuba version, variant, spp, seed, seconds) and the per-object pixel disks used by the
comparison test (for MetalRoughSpheres: one disk per sphere, 0.6 of its projected radius).
"""
import argparse
import json
import math
import os
import shutil
import sys
import tempfile
import time
import tomllib

import numpy as np


# ------------------------------------------------------------------ glTF
def quat_to_matrix(q):
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def trs(t, r, s):
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(r) * np.asarray(s, dtype=np.float64)[None, :]
    m[:3, 3] = t
    return m


class Gltf:
    def __init__(self, path):
        self.path = path
        self.dir = os.path.dirname(path)
        with open(path) as f:
            self.doc = json.load(f)
        self.buffers = []
        for b in self.doc["buffers"]:
            with open(os.path.join(self.dir, b["uri"]), "rb") as f:
                self.buffers.append(f.read())

    def accessor(self, i):
        a = self.doc["accessors"][i]
        view = self.doc["bufferViews"][a["bufferView"]]
        dtype = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}[a["componentType"]]
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a["type"]]
        stride = view.get("byteStride", 0)
        start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
        item = np.dtype(dtype).itemsize * width
        if stride and stride != item:
            raw = np.frombuffer(self.buffers[view["buffer"]], np.uint8, stride * (a["count"] - 1) + item, start)
            rows = np.lib.stride_tricks.as_strided(raw, (a["count"], item), (stride, 1))
            out = np.frombuffer(rows.copy().tobytes(), dtype).reshape(a["count"], width)
        else:
            out = np.frombuffer(self.buffers[view["buffer"]], dtype, a["count"] * width, start).reshape(a["count"], width)
        if a.get("normalized"):
            raise ValueError("normalized accessors are not supported")
        return out if width > 1 else out[:, 0]

    def local(self, node):
        if "matrix" in node:
            return np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T
        return trs(node.get("translation", [0, 0, 0]), node.get("rotation", [0, 0, 0, 1]), node.get("scale", [1, 1, 1]))

    def placements(self, root):
        """(world matrix, mesh index, node name) of every mesh instance of the default scene."""
        out = []

        def walk(i, parent):
            node = self.doc["nodes"][i]
            m = parent @ self.local(node)
            if "mesh" in node:
                inst = node.get("extensions", {}).get("EXT_mesh_gpu_instancing")
                if inst:
                    att = inst["attributes"]
                    n = self.doc["accessors"][next(iter(att.values()))]["count"]
                    t = self.accessor(att["TRANSLATION"]) if "TRANSLATION" in att else np.zeros((n, 3))
                    r = self.accessor(att["ROTATION"]) if "ROTATION" in att else np.tile([0, 0, 0, 1.0], (n, 1))
                    s = self.accessor(att["SCALE"]) if "SCALE" in att else np.ones((n, 3))
                    for k in range(n):
                        out.append((m @ trs(t[k], r[k], s[k]), node["mesh"], "%s#%d" % (node.get("name", i), k)))
                else:
                    out.append((m, node["mesh"], node.get("name", str(i))))
            for c in node.get("children", []):
                walk(c, m)

        for i in self.doc["scenes"][self.doc.get("scene", 0)]["nodes"]:
            walk(i, root)
        return out


def write_ply(path, positions, normals, uvs, faces):
    has_uv = uvs is not None
    header = ["ply", "format binary_little_endian 1.0", "element vertex %d" % len(positions),
              "property float x", "property float y", "property float z",
              "property float nx", "property float ny", "property float nz"]
    if has_uv:
        header += ["property float u", "property float v"]
    header += ["element face %d" % len(faces), "property list uchar int vertex_indices", "end_header", ""]
    cols = [positions, normals] + ([uvs] if has_uv else [])
    with open(path, "wb") as f:
        f.write("\n".join(header).encode())
        f.write(np.hstack(cols).astype("<f4").tobytes())
        rec = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
        rec["n"] = 3
        rec["i"] = faces
        f.write(rec.tobytes())


# ------------------------------------------------------------------ the glTF BSDF
def register_gltf_bsdf(mi, dr):
    """Registers the plugin `gltf_metal_rough`: appendix B of the glTF 2.0 specification."""

    class GltfMetalRough(mi.BSDF):
        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.base = props.get("base_color")            # texture (sRGB decoded) or None
            self.base_factor = mi.Color3f(props.get("base_factor", mi.ScalarColor3f(1, 1, 1)))
            self.mr = props.get("metal_rough")              # texture: G roughness, B metallic
            self.metallic = mi.Float(props.get("metallic", 1.0))
            self.roughness = mi.Float(props.get("roughness", 1.0))
            self.normal_map = props.get("normal_map")       # texture, linear
            self.min_alpha = 1e-3                           # Prism's floor (roughness 0)
            flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [flags]
            self.m_flags = flags

        # -- material inputs at a hit
        def inputs(self, si, active):
            base = self.base_factor
            if self.base is not None:
                base = base * self.base.eval(si, active)
            metallic, rough = self.metallic, self.roughness
            if self.mr is not None:
                t = self.mr.eval(si, active)
                rough = rough * t.y
                metallic = metallic * t.z
            alpha = dr.maximum(rough * rough, self.min_alpha)
            return base, metallic, alpha

        # -- the shading frame: Mitsuba's, or the normal-mapped one (world space)
        def frame(self, si, active):
            if self.normal_map is None:
                return si.sh_frame
            n = si.sh_frame.n
            t = dr.normalize(si.dp_du - n * dr.dot(n, si.dp_du))
            b = dr.cross(n, t)
            b = dr.select(dr.dot(b, si.dp_dv) < 0, -b, b)
            # glTF: green is "up" in the image, towards decreasing v.
            c = self.normal_map.eval(si, active) * 2 - 1
            m = dr.normalize(t * c.x - b * c.y + n * c.z)
            return mi.Frame3f(m)

        def local_dirs(self, si, wo_local, active):
            """Viewer and light directions in the (possibly normal-mapped) frame."""
            if self.normal_map is None:
                return si.wi, wo_local
            f = self.frame(si, active)
            v = f.to_local(si.to_world(si.wi))
            l = f.to_local(si.to_world(wo_local)) if wo_local is not None else None
            return v, l

        def brdf_cos(self, base, metallic, alpha, v, l):
            cos_v, cos_l = v.z, l.z
            h = dr.normalize(v + l)
            a2 = alpha * alpha
            sin2 = h.x * h.x + h.y * h.y
            t = sin2 + a2 * h.z * h.z
            d = a2 / (dr.pi * t * t)
            vis = 0.5 / (cos_l * dr.sqrt(a2 + (1 - a2) * cos_v * cos_v) + cos_v * dr.sqrt(a2 + (1 - a2) * cos_l * cos_l))
            voh = dr.maximum(dr.dot(v, h), 0.0)
            w = dr.power(1 - voh, 5)
            f_metal = base + (1 - base) * w
            f_diel = 0.04 + 0.96 * w
            spec = d * vis
            value = metallic * f_metal * spec + (1 - metallic) * (f_diel * spec + (1 - f_diel) * base / dr.pi)
            ok = (cos_v > 0) & (cos_l > 0) & (h.z > 0)
            return dr.select(ok, value * cos_l, 0.0)

        def spec_prob(self, metallic):
            return 0.5 + 0.5 * metallic

        def pdf_local(self, metallic, alpha, v, l):
            h = dr.normalize(v + l)
            a2 = alpha * alpha
            sin2 = h.x * h.x + h.y * h.y
            t = sin2 + a2 * h.z * h.z
            d = a2 / (dr.pi * t * t)
            p_spec = d * h.z / (4 * dr.abs(dr.dot(l, h)))
            p_diff = dr.maximum(l.z, 0.0) / dr.pi
            ps = self.spec_prob(metallic)
            ok = (v.z > 0) & (l.z > 0) & (h.z > 0)
            return dr.select(ok, ps * p_spec + (1 - ps) * p_diff, 0.0)

        def sample(self, ctx, si, sample1, sample2, active):
            base, metallic, alpha = self.inputs(si, active)
            v, _ = self.local_dirs(si, None, active)
            ps = self.spec_prob(metallic)
            choose_spec = sample1 < ps
            # Classic GGX sampling of the normal distribution D(h) cos(h).
            tan2 = alpha * alpha * sample2.x / dr.maximum(1 - sample2.x, 1e-7)
            cos_h = 1 / dr.sqrt(1 + tan2)
            sin_h = dr.sqrt(dr.maximum(1 - cos_h * cos_h, 0.0))
            phi = 2 * dr.pi * sample2.y
            h = mi.Vector3f(sin_h * dr.cos(phi), sin_h * dr.sin(phi), cos_h)
            l_spec = 2 * dr.dot(v, h) * h - v
            l_diff = mi.warp.square_to_cosine_hemisphere(sample2)
            l = dr.select(choose_spec, l_spec, l_diff)
            value = self.brdf_cos(base, metallic, alpha, v, l)
            pdf = self.pdf_local(metallic, alpha, v, l)
            # Back to Mitsuba's shading frame.
            if self.normal_map is not None:
                f = self.frame(si, active)
                wo = si.to_local(f.to_world(l))
            else:
                wo = l
            bs = mi.BSDFSample3f()
            bs.wo = wo
            bs.pdf = pdf
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
            bs.sampled_component = mi.UInt32(0)
            valid = active & (pdf > 0) & (v.z > 0) & (wo.z * si.wi.z > 0)
            weight = dr.select(valid, value / dr.maximum(pdf, 1e-20), 0.0)
            bs.pdf = dr.select(valid, pdf, 0.0)
            return bs, mi.Color3f(weight)

        def eval(self, ctx, si, wo, active):
            base, metallic, alpha = self.inputs(si, active)
            v, l = self.local_dirs(si, wo, active)
            ok = active & (wo.z * si.wi.z > 0)
            return dr.select(ok, mi.Color3f(self.brdf_cos(base, metallic, alpha, v, l)), 0.0)

        def pdf(self, ctx, si, wo, active):
            _, metallic, alpha = self.inputs(si, active)
            v, l = self.local_dirs(si, wo, active)
            ok = active & (wo.z * si.wi.z > 0)
            return dr.select(ok, self.pdf_local(metallic, alpha, v, l), 0.0)

        def eval_pdf(self, ctx, si, wo, active):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def traverse(self, callback):
            pass

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            return "GltfMetalRough[]"

    mi.register_bsdf("gltf_metal_rough", lambda props: GltfMetalRough(props))


def bitmap(mi, gl, tex_index, srgb):
    tex = gl.doc["textures"][tex_index]
    img = gl.doc["images"][tex["source"]]
    sampler = gl.doc.get("samplers", [{}])[tex["sampler"]] if "sampler" in tex else {}
    wrap = {10497: "repeat", 33071: "clamp", 33648: "mirror"}
    return mi.load_dict({
        "type": "bitmap",
        "filename": os.path.join(gl.dir, img["uri"]),
        "raw": not srgb,
        "filter_type": "bilinear" if sampler.get("magFilter", 9729) == 9729 else "nearest",
        "wrap_mode": wrap[sampler.get("wrapS", 10497)],
    })


def material(mi, gl, index):
    props = {"type": "gltf_metal_rough"}
    mat = gl.doc["materials"][index] if index is not None else {}
    unsupported = set(mat.get("extensions", {})) - set()
    if unsupported:
        raise ValueError("material %r: extensions %s are not converted" % (mat.get("name"), sorted(unsupported)))
    if mat.get("alphaMode", "OPAQUE") != "OPAQUE":
        raise ValueError("material %r: alpha modes are not converted" % mat.get("name"))
    pbr = mat.get("pbrMetallicRoughness", {})
    f = pbr.get("baseColorFactor", [1, 1, 1, 1])
    props["base_factor"] = mi.ScalarColor3f(*f[:3])
    props["metallic"] = float(pbr.get("metallicFactor", 1.0))
    props["roughness"] = float(pbr.get("roughnessFactor", 1.0))
    if "baseColorTexture" in pbr:
        props["base_color"] = bitmap(mi, gl, pbr["baseColorTexture"]["index"], True)
    if "metallicRoughnessTexture" in pbr:
        props["metal_rough"] = bitmap(mi, gl, pbr["metallicRoughnessTexture"]["index"], False)
    if "normalTexture" in mat:
        if mat["normalTexture"].get("scale", 1.0) != 1.0:
            raise ValueError("normal texture scales are not converted")
        props["normal_map"] = bitmap(mi, gl, mat["normalTexture"]["index"], False)
    if any(c > 0 for c in mat.get("emissiveFactor", [0, 0, 0])):
        raise ValueError("emissive glTF materials are not converted")
    bsdf = {"type": "twosided", "bsdf": props} if mat.get("doubleSided", False) else props
    return mi.load_dict(bsdf)


# ------------------------------------------------------------------ the scene
def look_at_matrix(eye, target, up):
    """Prism's camera frame as a world matrix (Mitsuba's look_at convention)."""
    import mitsuba as mi
    return mi.ScalarTransform4f().look_at(origin=list(map(float, eye)), target=list(map(float, target)), up=list(map(float, up)))


def project(eye, target, up, vfov, width, height, p):
    """Pixel coordinates (x right, y down, pixel centres at +0.5) of world point p for Prism's pinhole."""
    eye, target, up, p = (np.asarray(a, dtype=np.float64) for a in (eye, target, up, p))
    w = eye - target
    w /= np.linalg.norm(w)
    u = np.cross(up, w)
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    d = p - eye
    z = -np.dot(d, w)
    half = math.tan(math.radians(vfov) / 2)
    sx = np.dot(d, u) / (z * half * width / height)
    sy = np.dot(d, v) / (z * half)
    return (0.5 + 0.5 * sx) * width, (0.5 - 0.5 * sy) * height, z


def build(mi, scene_path, tmp, spp):
    with open(scene_path, "rb") as f:
        desc = tomllib.load(f)
    base = os.path.dirname(os.path.abspath(scene_path))
    st = desc.get("settings", {})
    width, height = int(st["width"]), int(st["height"])
    max_depth = int(st.get("max_depth", 8))
    cam = desc["camera"]
    up = cam.get("up", [0, 1, 0])
    for key in cam:
        if key not in ("look_from", "look_at", "up", "vfov"):
            raise ValueError("camera key %r is not converted" % key)
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": max_depth + 1, "hide_emitters": False},
        "sensor": {
            "type": "perspective", "fov": float(cam["vfov"]), "fov_axis": "y",
            "to_world": look_at_matrix(cam["look_from"], cam["look_at"], up),
            "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"},
                     "pixel_format": "rgb", "component_format": "float32"},
            "sampler": {"type": "independent", "sample_count": spp},
        },
    }
    env = desc.get("environment")
    if env:
        if "path" in env:
            raise ValueError("environment maps are not converted (use a colour)")
        c = env["color"]
        c = [c] * 3 if isinstance(c, (int, float)) else c
        k = float(env.get("intensity", 1.0))
        scene["environment"] = {"type": "constant", "radiance": {"type": "rgb", "value": [k * x for x in c]}}
    materials = desc.get("materials", {})
    for i, obj in enumerate(desc.get("objects", [])):
        shape = obj["shape"]
        mat = obj["material"]
        mat = materials[mat] if isinstance(mat, str) else mat
        if shape["type"] != "polygon" or "emission" not in mat:
            raise ValueError("object %r: only emissive polygons are converted" % obj.get("name"))
        e = mat["emission"]
        e = [e] * 3 if isinstance(e, (int, float)) else e
        vs = np.array(shape["vertices"], dtype=np.float64)
        n = np.cross(vs[1] - vs[0], vs[2] - vs[0])
        n /= np.linalg.norm(n)
        faces = np.array([[0, k, k + 1] for k in range(1, len(vs) - 1)], dtype=np.int32)
        fn = os.path.join(tmp, "light%d.ply" % i)
        write_ply(fn, vs, np.tile(n, (len(vs), 1)), None, faces)
        scene["light%d" % i] = {"type": "ply", "filename": fn, "face_normals": True,
                                "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}},
                                "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [float(x) for x in e]}}}
    placements = []
    for g in desc.get("gltf", []):
        gl = Gltf(os.path.normpath(os.path.join(base, g["path"])))
        root = np.eye(4)
        root[:3, :3] *= float(g.get("scale", 1.0))
        root[:3, 3] = g.get("translate", [0, 0, 0])
        mats = {}
        for k, (m, mesh, name) in enumerate(gl.placements(root)):
            placements.append((m, mesh, name, gl))
            for p, prim in enumerate(gl.doc["meshes"][mesh]["primitives"]):
                if prim.get("mode", 4) != 4:
                    raise ValueError("mesh %d: only triangle lists are converted" % mesh)
                att = prim["attributes"]
                pos = gl.accessor(att["POSITION"]).astype(np.float64)
                nor = gl.accessor(att["NORMAL"]).astype(np.float64)
                uv = gl.accessor(att["TEXCOORD_0"]) if "TEXCOORD_0" in att else None
                faces = (gl.accessor(prim["indices"]) if "indices" in prim else np.arange(len(pos))).astype(np.int32).reshape(-1, 3)
                # Bake the placement into the vertices (Mitsuba's PLY shapes are placed the same way).
                wp = pos @ m[:3, :3].T + m[:3, 3]
                nm = np.linalg.inv(m[:3, :3]).T
                wn = nor @ nm.T
                wn /= np.linalg.norm(wn, axis=1, keepdims=True)
                if np.linalg.det(m[:3, :3]) < 0:
                    faces = faces[:, ::-1]
                fn = os.path.join(tmp, "m%d_%d.ply" % (k, p))
                write_ply(fn, wp, wn, uv, faces)
                key = prim.get("material")
                if key not in mats:
                    mats[key] = material(mi, gl, key)
                scene["mesh%d_%d_%d" % (len(placements), k, p)] = {"type": "ply", "filename": fn, "bsdf": mats[key]}
    geometry = dict(width=width, height=height, eye=cam["look_from"], target=cam["look_at"], up=up, vfov=float(cam["vfov"]))
    return scene, placements, geometry


def disks(placements, geometry, fraction=0.6):
    """One pixel disk per placed mesh: its bounding sphere's projection, `fraction` of the radius."""
    out = []
    for m, mesh, name, gl in placements:
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for prim in gl.doc["meshes"][mesh]["primitives"]:
            a = gl.doc["accessors"][prim["attributes"]["POSITION"]]
            lo, hi = np.minimum(lo, a["min"]), np.maximum(hi, a["max"])
        c = m[:3, :3] @ ((lo + hi) / 2) + m[:3, 3]
        r = np.linalg.norm(m[:3, :3] @ ((hi - lo) / 2)) / math.sqrt(3)
        x, y, z = project(geometry["eye"], geometry["target"], geometry["up"], geometry["vfov"],
                          geometry["width"], geometry["height"], c)
        pix = r / (z * math.tan(math.radians(geometry["vfov"]) / 2)) * geometry["height"] / 2
        out.append({"name": name, "x": x, "y": y, "r": fraction * pix})
    return out


def write_exr(path, img):
    import OpenEXR
    img = np.ascontiguousarray(img[..., :3], dtype=np.float16)  # half floats: 3 digits, plenty for 1 % comparisons
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, {"RGB": img}) as f:
        f.write(path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene")
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--pass-spp", type=int, default=64)
    ap.add_argument("--disks", action="store_true", help="write per-mesh pixel disks into the .json")
    a = ap.parse_args()
    import drjit as dr
    import mitsuba as mi
    mi.set_variant(a.variant)
    register_gltf_bsdf(mi, dr)
    tmp = tempfile.mkdtemp(prefix="prism_ref_")
    try:
        desc, placements, geometry = build(mi, a.scene, tmp, a.pass_spp)
        scene = mi.load_dict(desc)
    finally:
        shutil.rmtree(tmp)
    t0 = time.perf_counter()
    acc = None
    passes = (a.spp + a.pass_spp - 1) // a.pass_spp
    for p in range(passes):
        img = np.array(mi.render(scene, spp=a.pass_spp, seed=a.seed * 1000003 + p), dtype=np.float64)
        acc = img if acc is None else acc + img
        print("pass %d/%d" % (p + 1, passes), file=sys.stderr, flush=True)
    img = (acc / passes).astype(np.float32)
    seconds = time.perf_counter() - t0
    if not np.isfinite(img).all():
        sys.exit("error: the reference has non-finite pixels")
    write_exr(a.output, img)
    meta = {"renderer": "Mitsuba %s" % mi.__version__, "variant": a.variant, "integrator": "path",
            "spp": passes * a.pass_spp, "seed": a.seed, "seconds": round(seconds, 1),
            "scene": os.path.basename(a.scene), "script": "tests/references/mitsuba_reference.py"}
    if a.disks:
        meta["disks"] = disks(placements, geometry)
    with open(os.path.splitext(a.output)[0] + ".json", "w") as f:
        json.dump(meta, f, indent=1)
    print("%s %s: %d spp in %.1f s -> %s" % (meta["renderer"], a.variant, meta["spp"], seconds, a.output))


if __name__ == "__main__":
    main()
