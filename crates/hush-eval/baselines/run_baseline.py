#!/usr/bin/env python3
"""Runs a Python denoiser baseline for hush_eval::external (one process per batch of images).

Usage: python run_baseline.py JOB_DIR
JOB_DIR/job.json: {"method": "bm3d" | "oidn", "repeats": N, "items": [{"color": "in_0.npy",
"albedo": "alb_0.npy" | null, "normal": "nrm_0.npy" | null, "sigma": float | null, "out": "out_0.npy"}, ...]}.
Images are float32 .npy arrays of shape (height, width, 3).
- bm3d: `bm3d.bm3d_rgb(color, sigma)` on the tonemapped image hush wrote (values in [0, 1]); output clipped
  to [0, 1]. hush chose sigma and inverts the tonemap afterwards.
- oidn: `pyoidn.denoise(color, albedo, normal, hdr=True, quality="balanced")` on linear HDR colour, with the
  features that are given (colour only when both are missing: albedo without normal is also allowed by OIDN).
  With `"weights": "weights.tza"` in the job: OIDN's C API (the library inside pyoidn) with those weights set
  as the RT filter's `weights` data, `hdr` on, everything else default: what `oidnDenoise -w` does.
Timing: each item is denoised 1 + N times; the first (warm-up) is discarded and the median of the other N
is reported, so Python and library start-up are not counted.
Writes JOB_DIR/result.json: {"seconds": [...], "versions": {...}}.
Exit code 3 with {"missing": "<module>", "error": "..."} in result.json when a package is not installed.
"""
import json
import os
import statistics
import sys
import time


def main():
    job_dir = sys.argv[1]
    with open(os.path.join(job_dir, "job.json")) as f:
        job = json.load(f)
    method = job["method"]
    module = {"bm3d": "bm3d", "oidn": "pyoidn"}[method]
    try:
        import numpy as np
        lib = __import__(module)
    except ImportError as e:
        with open(os.path.join(job_dir, "result.json"), "w") as f:
            json.dump({"missing": getattr(e, "name", None) or module, "error": str(e)}, f)
        sys.exit(3)

    def load(name):
        return None if name is None else np.ascontiguousarray(np.load(os.path.join(job_dir, name)), np.float32)

    if method == "bm3d":
        def run(item, color, albedo, normal):
            return np.clip(lib.bm3d_rgb(color, item["sigma"]), 0.0, 1.0)
    elif job.get("weights"):
        with open(os.path.join(job_dir, job["weights"]), "rb") as f:
            weights = f.read()
        run = oidn_with_weights(lib, np, weights)
    else:
        def run(item, color, albedo, normal):
            return lib.denoise(color, albedo, normal, hdr=True, quality="balanced")

    seconds = []
    for item in job["items"]:
        color, albedo, normal = load(item["color"]), load(item.get("albedo")), load(item.get("normal"))
        out = run(item, color, albedo, normal)
        times = []
        for _ in range(max(1, int(job.get("repeats", 1)))):
            start = time.perf_counter()
            out = run(item, color, albedo, normal)
            times.append(time.perf_counter() - start)
        seconds.append(statistics.median(times))
        np.save(os.path.join(job_dir, item["out"]), np.ascontiguousarray(out, dtype=np.float32))
    versions = {"numpy": np.__version__, module: getattr(lib, "__version__", None)}
    try:
        from importlib.metadata import version
        versions[module] = version({"bm3d": "bm3d", "pyoidn": "pyoidn"}[module])
    except Exception:
        pass
    with open(os.path.join(job_dir, "result.json"), "w") as f:
        json.dump({"seconds": seconds, "versions": versions}, f)


def oidn_with_weights(pyoidn, np, weights):
    """A denoise function that runs OIDN's RT filter with custom TZA weights through its C API (ctypes)."""
    import ctypes

    path = os.path.join(os.path.dirname(pyoidn.__file__), "oidn", "lib", "libOpenImageDenoise.so")
    c = ctypes.CDLL(path)
    c.oidnNewDevice.restype = ctypes.c_void_p
    c.oidnNewDevice.argtypes = [ctypes.c_int]
    c.oidnCommitDevice.argtypes = [ctypes.c_void_p]
    c.oidnNewFilter.restype = ctypes.c_void_p
    c.oidnNewFilter.argtypes = [ctypes.c_void_p, ctypes.c_char_p]
    c.oidnSetSharedFilterImage.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_void_p, ctypes.c_int,
                                           ctypes.c_size_t, ctypes.c_size_t, ctypes.c_size_t, ctypes.c_size_t,
                                           ctypes.c_size_t]
    c.oidnSetSharedFilterData.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_void_p, ctypes.c_size_t]
    c.oidnSetFilterBool.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_bool]
    c.oidnCommitFilter.argtypes = [ctypes.c_void_p]
    c.oidnExecuteFilter.argtypes = [ctypes.c_void_p]
    c.oidnGetDeviceError.restype = ctypes.c_int
    c.oidnGetDeviceError.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_char_p)]
    device = c.oidnNewDevice(1)  # OIDN_DEVICE_TYPE_CPU
    c.oidnCommitDevice(device)
    blob = ctypes.create_string_buffer(weights, len(weights))
    float3 = 3  # OIDN_FORMAT_FLOAT3

    def check(what):
        message = ctypes.c_char_p()
        if c.oidnGetDeviceError(device, ctypes.byref(message)) != 0:
            raise RuntimeError(f"OIDN {what}: {message.value.decode() if message.value else 'error'}")

    def run(item, color, albedo, normal):
        height, width, _ = color.shape
        out = np.zeros_like(color)
        flt = c.oidnNewFilter(device, b"RT")
        images = [(b"color", color), (b"output", out)]
        if albedo is not None:
            images.append((b"albedo", albedo))
        if normal is not None:
            images.append((b"normal", normal))
        for name, image in images:
            c.oidnSetSharedFilterImage(flt, name, image.ctypes.data, float3, width, height, 0, 0, 0)
        c.oidnSetFilterBool(flt, b"hdr", True)
        c.oidnSetSharedFilterData(flt, b"weights", blob, len(weights))
        c.oidnCommitFilter(flt)
        check("commit")
        c.oidnExecuteFilter(flt)
        check("execute")
        c.oidnReleaseFilter(ctypes.c_void_p(flt))
        return out

    return run


if __name__ == "__main__":
    main()
