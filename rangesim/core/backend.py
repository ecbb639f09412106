"""Mitsuba 3 / Dr.Jit variant selection, done once per process.

``cuda_ad_rgb`` when Dr.Jit finds a CUDA device, else ``llvm_ad_rgb``; the environment
variable ``RANGESIM_VARIANT`` overrides both. Also: whether the scan's casts ask Embree for
coherent traversal (:func:`coherent_rays`; ``RANGESIM_COHERENT_RAYS`` overrides).
"""
from __future__ import annotations

import functools
import os
from types import ModuleType

from rangesim.core.errors import RangesimError


def choose_variant() -> str:
    """Name of the Mitsuba variant this process should use."""
    override = os.environ.get("RANGESIM_VARIANT", "").strip()
    if override:
        return override
    import drjit as dr

    return "cuda_ad_rgb" if dr.has_backend(dr.JitBackend.CUDA) else "llvm_ad_rgb"


@functools.lru_cache(maxsize=1)
def coherent_rays() -> bool:
    """Whether the scan's camera and laser-shadow casts ask for Embree's coherent traversal.

    The rays and what they hit are the same either way (the hit points' last bits may
    differ: 8 of 1M pixels' depth by up to 4 um at 1.3M triangles); only the speed changes,
    and which is faster depends on the CPU's vector width: Embree traces a coherent stream
    in packets of 16 rays with AVX-512 and of 8 with AVX2. On an AVX-512 Intel Xeon (2
    cores, 1024^2 rays) coherent casts were ~1.7x faster (55 -> 33 ms at 327k triangles);
    on an AVX2-only AMD EPYC the bare cast in 4 x 4 tiles was slower (96 -> 104 ms at 327k,
    112 -> 144 ms at 1.3M) and the full scan at 5.2M triangles took 364 ms against 302 ms
    incoherent (the same within noise at 327k and 1.3M). So: coherent where the CPU reports
    AVX-512 (Linux ``/proc/cpuinfo``; True where that cannot be read), and on the GPU
    Mitsuba ignores the flag. ``RANGESIM_COHERENT_RAYS`` = 1 / 0 overrides.
    """
    override = os.environ.get("RANGESIM_COHERENT_RAYS", "").strip().lower()
    if override:
        if override not in ("0", "1", "true", "false", "yes", "no"):
            raise RangesimError(f"RANGESIM_COHERENT_RAYS must be 1 or 0, not {override!r}",
                                source="RANGESIM_COHERENT_RAYS")
        return override in ("1", "true", "yes")
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return "avx512f" in line.split()
    except OSError:
        pass
    return True


def mitsuba() -> ModuleType:
    """The ``mitsuba`` module with a variant set (choosing one on first use)."""
    import mitsuba as mi

    if mi.variant() is None:
        variant = choose_variant()
        if variant not in mi.variants():
            raise RangesimError(
                f"unknown Mitsuba variant {variant!r}; available: {', '.join(mi.variants())}",
                source="RANGESIM_VARIANT",
            )
        try:
            mi.set_variant(variant)
        except Exception as exc:  # e.g. cuda requested without a GPU
            raise RangesimError(f"cannot use Mitsuba variant {variant!r}: {exc}") from exc
    return mi


def aligned(a, align: int = 64):
    """A copy of the NumPy array ``a`` starting on an ``align``-byte boundary, for Dr.Jit.

    Dr.Jit's LLVM backend reads a NumPy array in place and compiles its kernels for the array's
    alignment: arrays at other offsets (NumPy aligns to 16 bytes; arrays under malloc's mmap
    threshold, ~128 KB, land anywhere on that grid) would compile new variants of the same
    kernels, at random, and a new image size would compile again. Every image-sized array
    handed to Dr.Jit goes through here.
    """
    import numpy as np

    a = np.ascontiguousarray(a)
    buf = np.empty(a.nbytes + align, np.uint8)
    start = (-buf.ctypes.data) % align
    out = buf[start:start + a.nbytes].view(a.dtype).reshape(a.shape)
    out[...] = a
    return out


def opaque_transform(matrix):
    """``mi.Transform4f`` of a 4x4 matrix whose entries enter kernels as opaque variables.

    A transform built from Python floats bakes them into the kernels as literals, so every
    new camera pose compiles the scan's kernels again (about 70 ms on a CPU core); with
    opaque entries a new pose reuses them.
    """
    import drjit as dr
    import numpy as np

    mi = mitsuba()
    m = np.asarray(matrix, dtype=np.float64)
    return mi.Transform4f(mi.Matrix4f([[dr.opaque(mi.Float, float(m[r, c])) for c in range(4)] for r in range(4)]))


def opaque_point(point):
    """``mi.Point3f`` of a 3-vector whose coordinates enter kernels as opaque variables."""
    import drjit as dr

    mi = mitsuba()
    return mi.Point3f(*(dr.opaque(mi.Float, float(c)) for c in point))


def opaque_scalar(value, kind: str = "Float"):
    """A Dr.Jit scalar of type ``mi.<kind>`` (Float, Int32, UInt32) entering kernels as an opaque variable.

    Image sizes and focal lengths pass through this, so a scan at a new image size reuses the
    kernels compiled for another (a literal would be baked into each kernel).
    """
    import drjit as dr

    mi = mitsuba()
    cls = getattr(mi, kind)
    return dr.opaque(cls, int(value) if kind != "Float" else float(value))
