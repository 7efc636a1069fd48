"""Mitsuba 3 helper for `cargo xtask` (run with the venv's Python from `cargo xtask mitsuba setup`).
(Not named mitsuba.py: the script's folder comes first on sys.path and would shadow the package.)


  check   render a scene at low spp and compare its mean with a reference render
  bench   M samples per CPU-second and relMSE x CPU-seconds of Mitsuba's llvm_ad_rgb variant (--variant
          cuda_ad_rgb on an NVIDIA GPU, where M samples per wall second is the figure)
          (--width/--height/--max-depth set as hush's flags do, see load_scene)
  relmse  relMSE of any RGB EXR (e.g. hush's render) against a reference EXR

CPU time is the process's (all threads, user + system) from resource.getrusage. `bench` first
renders once untimed (scene load and JIT compilation; Dr.Jit caches the compiled kernels), then
times a second render with another seed, which reuses them: the kernel history records whether
every kernel launched during the timed render came from the cache.

relMSE = mean over pixels and R, G, B of (x - ref)^2 / (ref^2 + 1e-2).
"""

import argparse
import json
import os
import resource
import sys
import time

import numpy as np

VARIANT = "llvm_ad_rgb"


def cpu_seconds():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def read_rgb(path):
    """The R, G, B channels of an EXR (any other layers, e.g. hush's albedo.R, are ignored)."""
    import mitsuba as mi

    bmp = mi.Bitmap(path)
    names = [f.name for f in bmp.struct_()]
    arr = np.array(bmp, dtype=np.float64)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    try:
        idx = [names.index(c) for c in ("R", "G", "B")]
    except ValueError:
        sys.exit(f"{path}: no R, G, B channels (has {names})")
    return arr[:, :, idx]


def relmse(img, ref):
    if img.shape != ref.shape:
        sys.exit(f"image {img.shape} and reference {ref.shape} differ in size")
    return float(np.mean((img - ref) ** 2 / (ref**2 + 1e-2)))


def setup_mitsuba(threads):
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(VARIANT)
    if threads:
        dr.set_thread_count(threads)
    return dr, mi


def write_exr(mi, img, path):
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    tmp = path + ".tmp.exr"
    mi.Bitmap(img).write(tmp)
    os.replace(tmp, path)


def integrator_max_depth(path):
    """The path integrator's max_depth as the scene file states it (Mitsuba does not expose it)."""
    import xml.etree.ElementTree as ET

    node = ET.parse(path).getroot().find("integrator/integer[@name='max_depth']")
    return None if node is None else int(node.get("value"))


def load_scene(mi, path, width=None, height=None, max_depth=None):
    """The scene file as hush renders it with `--width`, `--height` and `--max-depth`: those set on the
    film and on a `path` integrator (the scene's own integrator, e.g. a path guider, is replaced), a
    reconstruction filter hush lacks (not box, tent or gaussian) set to the box hush uses for it, and film
    options Mitsuba 3 no longer has (Mitsuba 0.6's `highQualityEdges`) dropped. Returns the scene and the
    list of edits made (none without overrides)."""
    if width is None and height is None and max_depth is None:
        return mi.load_file(path), []
    import xml.etree.ElementTree as ET

    root = ET.parse(path).getroot()
    edits = []
    film = root.find("sensor/film")
    if film is None:
        sys.exit(f"{path}: no <sensor><film> to set the image size on")
    for name, value in (("width", width), ("height", height)):
        if value is not None:
            node = film.find(f"integer[@name='{name}']")
            if node is None:
                node = ET.SubElement(film, "integer", name=name)
            node.set("value", str(value))
            edits.append(f"film {name} {value}")
    for node in list(film):
        if node.get("name") in ("highQualityEdges", "high_quality_edges"):
            film.remove(node)
            edits.append(f"dropped film {node.get('name')} (not in Mitsuba 3)")
        elif node.tag == "rfilter" and node.get("type") not in ("box", "tent", "gaussian"):
            edits.append(f"rfilter {node.get('type')} -> box (what hush uses for it)")
            node.attrib = {"type": "box"}
            node[:] = []
    integrator = root.find("integrator")
    if integrator is None:
        integrator = ET.Element("integrator", type="path")
        root.insert(0, integrator)
    if integrator.get("type") != "path":
        edits.append(f"integrator {integrator.get('type')} -> path")
        integrator.attrib = {"type": "path"}
        integrator[:] = []
    if max_depth is not None:
        node = next((n for n in integrator if n.get("name") in ("max_depth", "maxDepth")), None)
        if node is None:
            node = ET.SubElement(integrator, "integer", name="max_depth")
        node.set("value", str(max_depth))
        edits.append(f"max_depth {max_depth}")
    mi.file_resolver().prepend(os.path.dirname(os.path.abspath(path)))
    return mi.load_string(ET.tostring(root, encoding="unicode")), edits


def cmd_check(a):
    dr, mi = setup_mitsuba(a.threads)
    scene = mi.load_file(a.scene)
    img = np.array(mi.render(scene, spp=a.spp, seed=1), dtype=np.float64)[:, :, :3]
    if a.out:
        write_exr(mi, img.astype(np.float32), a.out)
    if not np.isfinite(img).all():
        sys.exit("Mitsuba's render has NaN or Inf pixels")
    mean = img.mean(axis=(0, 1))
    print(f"mitsuba {mi.__version__} {VARIANT}: {img.shape[1]}x{img.shape[0]} at {a.spp} spp, mean RGB {mean}")
    if a.ref:
        ref = read_rgb(a.ref)
        ref_mean = ref.mean(axis=(0, 1))
        rel = np.abs(mean / ref_mean - 1)
        print(f"reference mean RGB {ref_mean}: relative difference {rel}, relMSE {relmse(img, ref):.4g}")
        if rel.max() > 0.01:
            sys.exit("Mitsuba's render does not match the reference: is the LLVM backend broken?")
    elif not (mean > 0).all():
        sys.exit("Mitsuba's render is black")


def cmd_bench(a):
    c_start = cpu_seconds()
    dr, mi = setup_mitsuba(a.threads)
    c0 = cpu_seconds()
    import_cpu = c0 - c_start
    scene, edits = load_scene(mi, a.scene, a.width, a.height, a.max_depth)
    load_cpu = cpu_seconds() - c0
    film = scene.sensors()[0].film()
    w, h = film.size()
    max_depth = a.max_depth if a.max_depth is not None else integrator_max_depth(a.scene)

    # Cold render: tracing, JIT compilation, then the render itself.
    c0, w0 = cpu_seconds(), time.perf_counter()
    np.array(mi.render(scene, spp=a.spp, seed=a.seed + 1000))
    cold_cpu, cold_wall = cpu_seconds() - c0, time.perf_counter() - w0

    # Timed render with another seed: the kernels come from the cache.
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()  # clears it
    c0, w0 = cpu_seconds(), time.perf_counter()
    img = np.array(mi.render(scene, spp=a.spp, seed=a.seed), dtype=np.float64)[:, :, :3]
    cpu, wall = cpu_seconds() - c0, time.perf_counter() - w0
    hist = dr.kernel_history()
    launches = [k for k in hist if "cache_hit" in k]
    cache_hits = sum(1 for k in launches if k["cache_hit"])

    samples = w * h * a.spp
    out = {
        "renderer": f"mitsuba {mi.__version__}",
        "variant": VARIANT,
        "threads": dr.thread_count(),
        "scene": a.scene,
        "width": w,
        "height": h,
        "spp": a.spp,
        "max_depth": max_depth,
        "scene_edits": edits,
        "samples": samples,
        "cpu_seconds": cpu,
        "wall_seconds": wall,
        "msamples_per_cpu_second": samples / cpu / 1e6,
        "msamples_per_second": samples / wall / 1e6,
        "kernel_launches": len(launches),
        "kernel_cache_hits": cache_hits,
        "scene_load_cpu_seconds": load_cpu,
        "import_cpu_seconds": import_cpu,
        "cold_render_cpu_seconds": cold_cpu,
        "cold_render_wall_seconds": cold_wall,
        "measured": "getrusage(RUSAGE_SELF) user+system CPU of the second of two identical renders "
        "(different seeds); scene load and JIT compilation happen in the first",
    }
    if not np.isfinite(img).all():
        sys.exit("Mitsuba's render has NaN or Inf pixels")
    if a.out:
        write_exr(mi, img.astype(np.float32), a.out)
    if a.ref:
        r = relmse(img, read_rgb(a.ref))
        out["reference"] = a.ref
        out["relmse"] = r
        out["relmse_x_cpu_seconds"] = r * cpu
    text = json.dumps(out, indent=2)
    if a.stats:
        tmp = a.stats + ".tmp"
        with open(tmp, "w") as f:
            f.write(text)
        os.replace(tmp, a.stats)
    print(text)


def cmd_relmse(a):
    setup_mitsuba(None)
    img, ref = read_rgb(a.image), read_rgb(a.ref)
    r = relmse(img, ref)
    bad = int((~np.isfinite(img)).sum())
    print(json.dumps({"image": a.image, "reference": a.ref, "relmse": r, "nonfinite_values": bad}))


def main():
    global VARIANT
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("check")
    c.add_argument("--scene", required=True)
    c.add_argument("--spp", type=int, default=16)
    c.add_argument("--ref")
    c.add_argument("--out")
    c.add_argument("--threads", type=int, default=2)
    b = sub.add_parser("bench")
    b.add_argument("--scene", required=True)
    b.add_argument("--spp", type=int, default=64)
    b.add_argument("--threads", type=int, default=2)
    b.add_argument("--seed", type=int, default=1)
    b.add_argument("--width", type=int, help="film width (as hush's --width)")
    b.add_argument("--height", type=int, help="film height (as hush's --height)")
    b.add_argument("--max-depth", type=int, help="the path integrator's max_depth (as hush's --max-depth)")
    b.add_argument("--ref")
    b.add_argument("--out")
    b.add_argument("--stats")
    b.add_argument("--variant", default=VARIANT, help="Mitsuba's variant, e.g. cuda_ad_rgb on an NVIDIA GPU")
    r = sub.add_parser("relmse")
    r.add_argument("--image", required=True)
    r.add_argument("--ref", required=True)
    a = p.parse_args()
    VARIANT = getattr(a, "variant", VARIANT)
    {"check": cmd_check, "bench": cmd_bench, "relmse": cmd_relmse}[a.cmd](a)


if __name__ == "__main__":
    main()
