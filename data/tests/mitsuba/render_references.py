"""Regenerates the Mitsuba 3 references of this folder: every scene's files and its `mitsuba.exr`.

Run it with the venv of `cargo xtask mitsuba setup` (`cargo xtask mitsuba references` does):

    python render_references.py                  # every scene
    python render_references.py --only envmap    # one scene
    python render_references.py --scenes-only    # rewrite the scene files, render nothing
    python render_references.py --spp 256 --no-write   # quick noise estimate, writes no reference

This script is the source of the scenes: it writes `<name>/scene.xml`, the OBJ meshes, the
texture and the environment map, then renders each scene with Mitsuba (version pinned below,
variant llvm_ad_rgb, fixed seeds) in PASSES independent passes of spp/PASSES samples. The
reference is the mean of the passes; the spread of the passes gives the standard error of every
8×8 block mean, written with the render time to `<name>/reference.json` and summarized in
README.md's table. The scenes use only what hush's Mitsuba loader reads.
"""

import argparse
import json
import math
import os
import resource
import sys
import tempfile
import time

import numpy as np

MITSUBA_VERSION = "3.9.1"
VARIANT = "llvm_ad_rgb"
SEED = 1_000_003  # pass i renders with seed SEED + i
PASSES = 16
SIZE = 64
BLOCK = 8
MAX_DEPTH = 8
TARGET_SE = 0.003  # relative standard error of every 8×8 block mean, per channel

HERE = os.path.dirname(os.path.abspath(__file__))

# ---------------------------------------------------------------- geometry and images


def sphere_obj(center, radius, nu=48, nv=24):
    """A UV sphere of flat triangles, wound counter-clockwise seen from outside (rendered with
    face_normals, so both renderers see exactly these triangles)."""
    cx, cy, cz = center
    verts = []
    for j in range(nv + 1):
        th = math.pi * j / nv
        for i in range(nu):
            ph = 2 * math.pi * i / nu
            verts.append((cx + radius * math.sin(th) * math.cos(ph), cy + radius * math.cos(th), cz - radius * math.sin(th) * math.sin(ph)))
    faces = []
    idx = lambda i, j: j * nu + (i % nu) + 1  # noqa: E731
    for j in range(nv):
        for i in range(nu):
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            if j != 0:
                faces.append((a, d, b))
            if j != nv - 1:
                faces.append((b, d, c))
    lines = [f"v {x:.5f} {y:.5f} {z:.5f}" for x, y, z in verts] + [f"f {a} {b} {c}" for a, b, c in faces]
    text = "\n".join(lines) + "\n"
    check_outward(text, center)
    return text


def check_outward(obj_text, center):
    """Asserts every triangle's normal (counter-clockwise) points away from the centre."""
    v = [tuple(map(float, l.split()[1:])) for l in obj_text.splitlines() if l.startswith("v ")]
    f = [tuple(int(t) - 1 for t in l.split()[1:]) for l in obj_text.splitlines() if l.startswith("f ")]
    v = np.array(v)
    for a, b, c in f:
        n = np.cross(v[b] - v[a], v[c] - v[a])
        assert np.dot(n, (v[a] + v[b] + v[c]) / 3 - np.array(center)) > 0, "inward triangle"


def envmap_image(w=64, h=32):
    """Lat-long sky: a blue-to-white gradient above the horizon, brown ground below, and a
    2×2-pixel sun (radiance 400) at about 34° elevation."""
    img = np.zeros((h, w, 3), np.float32)
    for r in range(h):
        t = (r + 0.5) / h  # 0 = zenith, 1 = nadir
        if t < 0.5:
            s = t / 0.5
            img[r, :] = (1 - s) * np.array([0.25, 0.45, 1.0]) + s * np.array([1.0, 0.95, 0.9])
        else:
            img[r, :] = [0.35, 0.25, 0.15]
    for c in range(w):
        img[:, c] *= 1.0 + 0.25 * math.cos(2 * math.pi * (c + 0.5) / w)  # azimuthal variation
    img[9:11, 40:42] = [400.0, 360.0, 300.0]
    return img


def checker_image(n=16, cell=4):
    """8-bit sRGB checkerboard with a colour ramp (tests sRGB decoding, filtering and uv orientation)."""
    img = np.zeros((n, n, 3), np.uint8)
    for y in range(n):
        for x in range(n):
            if ((x // cell) + (y // cell)) % 2 == 0:
                img[y, x] = [230, 200 - 8 * y, 40 + 10 * x]
            else:
                img[y, x] = [30 + 12 * x, 60, 150 + 5 * y]
    return img


# ---------------------------------------------------------------- XML


def header(spp, origin="0, 0, 3.6", target="0, 0, 0", fov=40):
    return f"""<scene version="3.0.0">
  <integrator type="path">
    <integer name="max_depth" value="{MAX_DEPTH}"/>
  </integrator>
  <sensor type="perspective">
    <float name="fov" value="{fov}"/>
    <transform name="to_world">
      <lookat origin="{origin}" target="{target}" up="0, 1, 0"/>
    </transform>
    <sampler type="independent">
      <integer name="sample_count" value="{spp}"/>
    </sampler>
    <film type="hdrfilm">
      <integer name="width" value="{SIZE}"/>
      <integer name="height" value="{SIZE}"/>
      <rfilter type="box"/>
      <string name="pixel_format" value="rgb"/>
    </film>
  </sensor>
"""


def rect(transform, bsdf, extra=""):
    return f"""  <shape type="rectangle">
    <transform name="to_world">
{transform}
    </transform>
{bsdf}{extra}  </shape>
"""


# The ground of the open scenes: a 6×6 rectangle at y = −0.5, facing up.
GROUND = '      <scale value="3"/>\n      <rotate x="1" angle="-90"/>\n      <translate y="-0.5"/>'


def diffuse(rgb):
    return f"""    <bsdf type="diffuse">
      <rgb name="reflectance" value="{rgb}"/>
    </bsdf>
"""


def room(light=None, floor_bsdf=None, back_bsdf=None):
    """A 2×2×2 box open towards the camera (+z): white floor, ceiling and back, red left wall,
    green right wall, and a one-sided 1×1 area light under the ceiling facing down (large and
    dim, so that caustics and its reflections converge in reasonable time); `light=False` leaves
    the light out."""
    white = diffuse("0.75, 0.75, 0.75")
    walls = (
        rect('      <rotate x="1" angle="-90"/>\n      <translate y="-1"/>', floor_bsdf or white)
        + rect('      <rotate x="1" angle="90"/>\n      <translate y="1"/>', white)
        + rect('      <translate z="-1"/>', back_bsdf or white)
        + rect('      <rotate y="1" angle="90"/>\n      <translate x="-1"/>', diffuse("0.7, 0.1, 0.1"))
        + rect('      <rotate y="1" angle="-90"/>\n      <translate x="1"/>', diffuse("0.1, 0.6, 0.15"))
    )
    if light is False:
        return walls
    if light is None:
        light = ('      <scale value="0.5"/>\n      <rotate x="1" angle="90"/>\n      <translate y="0.99"/>', (5.0, 4.2, 3.0))
    transform, radiance = light
    r = ", ".join(f"{c:g}" for c in radiance)
    return (
        walls
        + rect(
            transform,
            diffuse("0, 0, 0"),
            f"""    <emitter type="area">
      <rgb name="radiance" value="{r}"/>
    </emitter>
""",
        )
    )


def obj(filename, bsdf):
    return f"""  <shape type="obj">
    <string name="filename" value="{filename}"/>
    <boolean name="face_normals" value="true"/>
{bsdf}  </shape>
"""


def footer():
    return "</scene>\n"


def analytic(kind, params, bsdf, transform="", emitter=None):
    """One of Mitsuba's analytic shapes (`sphere`, `disk`, `rectangle`, `cylinder`), with its own
    parameters, an optional to_world and an optional area emitter's radiance."""
    t = f'    <transform name="to_world">\n{transform}\n    </transform>\n' if transform else ""
    e = ""
    if emitter is not None:
        r = ", ".join(f"{c:g}" for c in emitter)
        e = f'    <emitter type="area">\n      <rgb name="radiance" value="{r}"/>\n    </emitter>\n'
    return f'  <shape type="{kind}">\n{params}{t}{bsdf}{e}  </shape>\n'


def two_spheres(spp, left_bsdf, right_bsdf):
    """The room with two spheres of radius 0.35 side by side on its floor."""
    files = {"left.obj": sphere_obj((-0.45, -0.65, 0.0), 0.35), "right.obj": sphere_obj((0.45, -0.65, 0.0), 0.35)}
    return files, header(spp) + room() + obj("left.obj", left_bsdf) + obj("right.obj", right_bsdf) + footer()


# ---------------------------------------------------------------- the scenes

# Each scene: (what it tests, spp, files {name: text|callable}, xml(spp) -> str).
SCENES = {}


def scene(name, tests, spp):
    def register(fn):
        SCENES[name] = dict(tests=tests, spp=spp, build=fn)
        return fn

    return register


SPHERE_C = (0.0, -0.55, 0.0)


@scene("diffuse-twosided", "Lambertian sphere; `twosided` diffuse panel seen from its back", 16384)
def _(spp):
    files = {"sphere.obj": sphere_obj((-0.45, -0.65, -0.3), 0.35)}
    panel = rect(
        '      <scale x="0.45" y="0.3"/>\n      <rotate x="1" angle="-150"/>\n      <translate x="0.35" y="-0.45" z="0"/>',
        """    <bsdf type="twosided">
      <bsdf type="diffuse">
        <rgb name="reflectance" value="0.8, 0.7, 0.2"/>
      </bsdf>
    </bsdf>
""",
    )
    xml = header(spp) + room() + obj("sphere.obj", diffuse("0.3, 0.5, 0.8")) + panel + footer()
    return files, xml


@scene("conductor", "smooth `conductor` (named material Au) sphere", 40960)
def _(spp):
    files = {"sphere.obj": sphere_obj(SPHERE_C, 0.45)}
    bsdf = """    <bsdf type="conductor">
      <string name="material" value="Au"/>
    </bsdf>
"""
    return files, header(spp) + room() + obj("sphere.obj", bsdf) + footer()


@scene("roughconductor", "`roughconductor` GGX, visible normals: alpha 0.05 (eta/k given) and 0.3 (Al)", 24576)
def _(spp):
    glossy = """    <bsdf type="roughconductor">
      <string name="distribution" value="ggx"/>
      <float name="alpha" value="0.05"/>
      <rgb name="eta" value="0.2004, 0.9240, 1.1022"/>
      <rgb name="k" value="3.9129, 2.4528, 2.1422"/>
    </bsdf>
"""
    rough = """    <bsdf type="roughconductor">
      <string name="distribution" value="ggx"/>
      <string name="material" value="Al"/>
      <float name="alpha" value="0.3"/>
    </bsdf>
"""
    return two_spheres(spp, glossy, rough)


@scene("dielectric", "smooth `dielectric` glass sphere (IOR 1.5), caustic on the floor", 49152)
def _(spp):
    files = {"sphere.obj": sphere_obj(SPHERE_C, 0.45)}
    bsdf = """    <bsdf type="dielectric">
      <float name="int_ior" value="1.5"/>
      <float name="ext_ior" value="1.0"/>
    </bsdf>
"""
    return files, header(spp) + room() + obj("sphere.obj", bsdf) + footer()


@scene("thindielectric", "`thindielectric` pane (IOR 1.5) in front of a diffuse sphere", 32768)
def _(spp):
    files = {"sphere.obj": sphere_obj((0.1, -0.65, -0.4), 0.35)}
    pane = rect(
        '      <scale x="0.6" y="0.45"/>\n      <rotate y="1" angle="25"/>\n      <translate x="-0.1" y="-0.45" z="0.35"/>',
        """    <bsdf type="thindielectric">
      <float name="int_ior" value="1.5"/>
      <float name="ext_ior" value="1.0"/>
    </bsdf>
""",
    )
    xml = header(spp) + room() + obj("sphere.obj", diffuse("0.8, 0.5, 0.2")) + pane + footer()
    return files, xml


@scene("roughdielectric", "`roughdielectric` GGX sphere (alpha 0.15, IOR 1.5)", 40960)
def _(spp):
    files = {"sphere.obj": sphere_obj(SPHERE_C, 0.45)}
    bsdf = """    <bsdf type="roughdielectric">
      <string name="distribution" value="ggx"/>
      <float name="alpha" value="0.15"/>
      <float name="int_ior" value="1.5"/>
      <float name="ext_ior" value="1.0"/>
    </bsdf>
"""
    return files, header(spp) + room() + obj("sphere.obj", bsdf) + footer()


@scene("plastic", "smooth `plastic` sphere (blue, IOR 1.49)", 16384)
def _(spp):
    files = {"sphere.obj": sphere_obj(SPHERE_C, 0.45)}
    bsdf = """    <bsdf type="plastic">
      <rgb name="diffuse_reflectance" value="0.1, 0.25, 0.7"/>
      <float name="int_ior" value="1.49"/>
    </bsdf>
"""
    return files, header(spp) + room() + obj("sphere.obj", bsdf) + footer()


@scene("roughplastic", "`roughplastic` GGX sphere (orange, alpha 0.2)", 24576)
def _(spp):
    files = {"sphere.obj": sphere_obj(SPHERE_C, 0.45)}
    bsdf = """    <bsdf type="roughplastic">
      <string name="distribution" value="ggx"/>
      <float name="alpha" value="0.2"/>
      <rgb name="diffuse_reflectance" value="0.8, 0.35, 0.05"/>
      <float name="int_ior" value="1.49"/>
    </bsdf>
"""
    return files, header(spp) + room() + obj("sphere.obj", bsdf) + footer()


@scene("beckmann", "Beckmann microfacets: `roughconductor` (Cu, alpha 0.15) and `roughplastic` (green, alpha 0.3) spheres", 16384)
def _(spp):
    metal = """    <bsdf type="roughconductor">
      <string name="distribution" value="beckmann"/>
      <string name="material" value="Cu"/>
      <float name="alpha" value="0.15"/>
    </bsdf>
"""
    plastic = """    <bsdf type="roughplastic">
      <string name="distribution" value="beckmann"/>
      <float name="alpha" value="0.3"/>
      <rgb name="diffuse_reflectance" value="0.15, 0.6, 0.2"/>
      <float name="int_ior" value="1.49"/>
    </bsdf>
"""
    return two_spheres(spp, metal, plastic)


@scene("textured", "`bitmap` (8-bit sRGB PNG, bilinear, repeat) as diffuse reflectance on floor and back wall", 16384)
def _(spp):
    tex = """    <bsdf type="diffuse">
      <texture type="bitmap" name="reflectance">
        <string name="filename" value="checker.png"/>
      </texture>
    </bsdf>
"""
    files = {"checker.png": checker_image}
    return files, header(spp) + room(floor_bsdf=tex, back_bsdf=tex) + footer()


@scene("envmap", "`envmap` emitter (64×32 EXR, sun + sky), no other light; diffuse and rough metal spheres", 16384)
def _(spp):
    files = {
        "sky.exr": envmap_image,
        "diffuse.obj": sphere_obj((-0.55, 0.0, 0.0), 0.5),
        "metal.obj": sphere_obj((0.6, -0.1, 0.3), 0.4),
    }
    ground = rect(GROUND, diffuse("0.5, 0.5, 0.5"))
    metal = """    <bsdf type="roughconductor">
      <string name="distribution" value="ggx"/>
      <string name="material" value="Cu"/>
      <float name="alpha" value="0.2"/>
    </bsdf>
"""
    env = """  <emitter type="envmap">
    <string name="filename" value="sky.exr"/>
  </emitter>
"""
    xml = (
        header(spp, origin="0, 1.2, 3.5", target="0, -0.1, 0", fov=45)
        + ground
        + obj("diffuse.obj", diffuse("0.7, 0.7, 0.7"))
        + obj("metal.obj", metal)
        + env
        + footer()
    )
    return files, xml


@scene("constant", "`constant` environment emitter only; diffuse and plastic spheres on a ground plane", 4096)
def _(spp):
    files = {"diffuse.obj": sphere_obj((-0.55, 0.0, 0.0), 0.5), "plastic.obj": sphere_obj((0.6, -0.1, 0.3), 0.4)}
    ground = rect(GROUND, diffuse("0.5, 0.5, 0.5"))
    plastic = """    <bsdf type="plastic">
      <rgb name="diffuse_reflectance" value="0.7, 0.15, 0.1"/>
    </bsdf>
"""
    env = """  <emitter type="constant">
    <rgb name="radiance" value="0.8, 0.9, 1.1"/>
  </emitter>
"""
    xml = (
        header(spp, origin="0, 1.2, 3.5", target="0, -0.1, 0", fov=45)
        + ground
        + obj("diffuse.obj", diffuse("0.7, 0.7, 0.7"))
        + obj("plastic.obj", plastic)
        + env
        + footer()
    )
    return files, xml


@scene("stiff", "stiff lighting: a 0.02×0.02 light of radiance ~1e4 (power of the other rooms' light), hidden from the camera; glossy metal + diffuse spheres", 65536)
def _(spp):
    files = {"metal.obj": sphere_obj((0.4, -0.65, -0.1), 0.35), "diffuse.obj": sphere_obj((-0.45, -0.65, 0.1), 0.35)}
    metal = """    <bsdf type="roughconductor">
      <string name="distribution" value="ggx"/>
      <string name="material" value="Ag"/>
      <float name="alpha" value="0.1"/>
    </bsdf>
"""
    # Same power as room()'s light: area 1 → 0.0004 (2500× smaller), radiance 2500× larger. It
    # faces away from the camera (down and to the back), so the camera sees only its black back.
    tiny = ('      <scale value="0.01"/>\n      <rotate x="1" angle="150"/>\n      <translate y="0.7" z="0.9"/>',
            (12500.0, 10500.0, 7500.0))
    xml = (
        header(spp)
        + room(light=tiny)
        + obj("metal.obj", metal)
        + obj("diffuse.obj", diffuse("0.6, 0.6, 0.6"))
        + footer()
    )
    return files, xml


@scene("analytic", "analytic `sphere` (textured), `cylinder` with a `disk` cap, `rectangle` walls; lit only by an emitting `sphere` and an emitting `disk`", 32768)
def _(spp):
    files = {"checker.png": checker_image}
    tex = """    <bsdf type="diffuse">
      <texture type="bitmap" name="reflectance">
        <string name="filename" value="checker.png"/>
      </texture>
    </bsdf>
"""
    plastic = """    <bsdf type="roughplastic">
      <string name="distribution" value="ggx"/>
      <float name="alpha" value="0.2"/>
      <rgb name="diffuse_reflectance" value="0.2, 0.35, 0.8"/>
    </bsdf>
"""
    xml = (
        header(spp)
        + room(light=False)
        # A textured sphere turned so that its texture's seam and poles face the camera's side.
        + analytic("sphere", "", tex, '      <scale value="0.35"/>\n      <rotate x="1" angle="-70"/>\n'
                   '      <rotate y="1" angle="30"/>\n      <translate x="-0.4" y="-0.65" z="-0.2"/>')
        + analytic("cylinder", '    <point name="p0" value="0.45, -1, -0.3"/>\n    <point name="p1" value="0.45, -0.3, -0.3"/>\n'
                   '    <float name="radius" value="0.25"/>\n', plastic)
        + analytic("disk", "", diffuse("0.8, 0.75, 0.2"), '      <scale value="0.25"/>\n      <rotate x="1" angle="-90"/>\n'
                   '      <translate x="0.45" y="-0.3" z="-0.3"/>')
        # The lights: a small sphere in front and a disk under the ceiling facing down.
        + analytic("sphere", '    <point name="center" value="-0.35, 0.35, 0.45"/>\n    <float name="radius" value="0.1"/>\n',
                   diffuse("0, 0, 0"), emitter=(30.0, 25.0, 18.0))
        + analytic("disk", "", diffuse("0, 0, 0"), '      <scale value="0.3"/>\n      <rotate x="1" angle="90"/>\n'
                   '      <translate x="0.2" y="0.99" z="-0.1"/>', emitter=(6.0, 5.5, 5.0))
        + footer()
    )
    return files, xml


@scene("spheres-sky", "four analytic spheres (diffuse, plastic, rough metal, glass) on a ground rectangle under a `constant` sky", 8192)
def _(spp):
    ground = rect(GROUND, diffuse("0.5, 0.5, 0.5"))
    metal = """    <bsdf type="roughconductor">
      <string name="distribution" value="ggx"/>
      <string name="material" value="Au"/>
      <float name="alpha" value="0.1"/>
    </bsdf>
"""
    glass = """    <bsdf type="dielectric">
      <float name="int_ior" value="1.5"/>
    </bsdf>
"""
    plastic = """    <bsdf type="plastic">
      <rgb name="diffuse_reflectance" value="0.7, 0.15, 0.1"/>
    </bsdf>
"""
    ball = lambda c, r, bsdf: analytic(  # noqa: E731
        "sphere", f'    <point name="center" value="{c}"/>\n    <float name="radius" value="{r}"/>\n', bsdf)
    env = """  <emitter type="constant">
    <rgb name="radiance" value="0.8, 0.9, 1.1"/>
  </emitter>
"""
    xml = (
        header(spp, origin="0, 1.2, 3.5", target="0, -0.1, 0", fov=45)
        + ground
        + ball("-0.9, -0.1, -0.2", 0.4, diffuse("0.7, 0.7, 0.7"))
        + ball("-0.05, -0.15, 0.3", 0.35, plastic)
        + ball("0.75, -0.05, -0.1", 0.45, metal)
        + ball("0.2, -0.3, 1.0", 0.2, glass)
        + env
        + footer()
    )
    return {}, xml


# ---------------------------------------------------------------- building and rendering


def cpu_seconds():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def write_files(mi, name, spp, root=HERE):
    folder = os.path.join(root, name)
    os.makedirs(folder, exist_ok=True)
    files, xml = SCENES[name]["build"](spp)
    for fname, content in files.items():
        path = os.path.join(folder, fname)
        if callable(content):
            img = content()
            mi.Bitmap(img, mi.Bitmap.PixelFormat.RGB).write(path)  # uint8 → sRGB PNG, float32 → EXR
        else:
            with open(path, "w") as f:
                f.write(content)
    with open(os.path.join(folder, "scene.xml"), "w") as f:
        f.write(xml)
    return folder


def block_stats(passes):
    """Per 8×8 block and channel: the mean over passes and its relative standard error."""
    k, h, w, c = passes.shape
    blocks = passes.reshape(k, h // BLOCK, BLOCK, w // BLOCK, BLOCK, c).mean(axis=(2, 4))
    mean = blocks.mean(axis=0)
    se = blocks.std(axis=0, ddof=1) / math.sqrt(k)
    lum_w = np.array([0.2126, 0.7152, 0.0722])
    lum = blocks @ lum_w
    lum_rel = lum.std(axis=0, ddof=1) / math.sqrt(k) / np.maximum(lum.mean(axis=0), 1e-12)
    valid = mean > 1e-3 * mean.max()
    rel = np.where(valid, se / np.maximum(mean, 1e-12), 0.0)
    return mean, rel, lum_rel


def render(mi, dr, name, spp, write):
    # A noise estimate (write=False) renders from a scratch copy and leaves this folder as it is.
    folder = write_files(mi, name, spp, HERE if write else tempfile.mkdtemp(prefix="mitsuba-ref-"))
    scene = mi.load_file(os.path.join(folder, "scene.xml"))
    per_pass = spp // PASSES
    assert per_pass * PASSES == spp, f"spp must be a multiple of {PASSES}"
    c0, w0 = cpu_seconds(), time.perf_counter()
    passes = []
    for i in range(PASSES):
        img = np.array(mi.render(scene, spp=per_pass, seed=SEED + i), dtype=np.float64)[:, :, :3]
        passes.append(img)
    cpu, wall = cpu_seconds() - c0, time.perf_counter() - w0
    passes = np.stack(passes)
    if not np.isfinite(passes).all():
        sys.exit(f"{name}: Mitsuba rendered NaN or Inf")
    ref = passes.mean(axis=0)
    _, rel, lum_rel = block_stats(passes)
    image_means = passes.mean(axis=(1, 2))  # per pass and channel
    image_mean = image_means.mean(axis=0)
    image_rel_se = image_means.std(axis=0, ddof=1) / math.sqrt(PASSES) / np.maximum(image_mean, 1e-12)
    stats = {
        "scene": name,
        "tests": SCENES[name]["tests"],
        "mitsuba": mi.__version__,
        "variant": VARIANT,
        "spp": spp,
        "passes": PASSES,
        "seeds": [SEED, SEED + PASSES - 1],
        "width": SIZE,
        "height": SIZE,
        "max_depth": MAX_DEPTH,
        "wall_seconds": round(wall, 2),
        "cpu_seconds": round(cpu, 2),
        "block": BLOCK,
        "block_rel_se_max": float(rel.max()),
        "block_rel_se_median": float(np.median(rel[rel > 0])),
        "block_luminance_rel_se_max": float(lum_rel.max()),
        "image_mean": [float(x) for x in image_mean],
        "image_mean_rel_se": [float(x) for x in image_rel_se],
        "block_rel_se": np.round(rel, 5).tolist(),
        "note": "relative standard error of each 8×8 block mean per R, G, B (rows, columns, channel), "
        f"from the spread of {PASSES} independent passes; channels darker than 1e-3 of the brightest are 0",
    }
    print(
        f"{name:18s} {spp:6d} spp  {wall:7.1f} s wall {cpu:7.1f} CPU-s  block rel SE max {rel.max() * 100:.3f} % "
        f"(median {stats['block_rel_se_median'] * 100:.3f} %, luminance max {lum_rel.max() * 100:.3f} %)",
        flush=True,
    )
    if write:
        mi.Bitmap(ref.astype(np.float32), mi.Bitmap.PixelFormat.RGB).write(os.path.join(folder, "mitsuba.exr"))
        with open(os.path.join(folder, "reference.json"), "w") as f:
            json.dump(stats, f, indent=1)
            f.write("\n")
    return stats


def readme_table():
    rows = []
    for name, s in SCENES.items():
        p = os.path.join(HERE, name, "reference.json")
        if not os.path.exists(p):
            continue
        with open(p) as f:
            r = json.load(f)
        rows.append(
            f"| `{name}` | {r['tests']} | {r['spp']} | {r['block_rel_se_max'] * 100:.2f} % | "
            f"{r['wall_seconds']:.0f} s ({r['cpu_seconds']:.0f} CPU-s) | {r['mitsuba']} `{r['variant']}` |"
        )
    head = "| scene | what it tests | spp | max block SE | render time | Mitsuba |\n|---|---|---|---|---|---|\n"
    return head + "\n".join(rows) + "\n"


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--only", action="append", help="render only this scene (repeatable)")
    p.add_argument("--spp", type=int, help="override every scene's spp (a multiple of 16)")
    p.add_argument("--no-write", action="store_true", help="write no reference (a noise estimate)")
    p.add_argument("--scenes-only", action="store_true", help="write the scene files, render nothing")
    p.add_argument("--threads", type=int, default=0, help="Dr.Jit threads (default: all cores)")
    a = p.parse_args()

    import drjit as dr
    import mitsuba as mi

    if mi.__version__ != MITSUBA_VERSION:
        sys.exit(f"these references are made with Mitsuba {MITSUBA_VERSION}, this is {mi.__version__}")
    mi.set_variant(VARIANT)
    if a.threads:
        dr.set_thread_count(a.threads)
    names = a.only or list(SCENES)
    for n in names:
        if n not in SCENES:
            sys.exit(f"unknown scene {n}; scenes: {', '.join(SCENES)}")
    for n in names:
        spp = a.spp or SCENES[n]["spp"]
        if a.scenes_only:
            write_files(mi, n, spp)
            continue
        s = render(mi, dr, n, spp, not a.no_write)
        if s["block_rel_se_max"] > TARGET_SE:
            print(f"  {n}: above the {TARGET_SE * 100:.1f} % target: needs about "
                  f"{spp * (s['block_rel_se_max'] / TARGET_SE) ** 2:.0f} spp", flush=True)
    if not a.no_write and not a.scenes_only:
        print(readme_table())


if __name__ == "__main__":
    main()
