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
    incoherent (the same within noise at 327k and 1.3M); on an AVX-512 AMD EPYC Zen 4 (2 cores)
    the full 1024^2 scan of the Green Piece took 0.17 s coherent against 0.20 s incoherent
    (medians of 5, interleaved). So: coherent where the CPU reports
    AVX-512 (Linux ``/proc/cpuinfo``; True where that cannot be read), and on the GPU
    Mitsuba ignores the flag. ``RANGESIM_COHERENT_RAYS`` = 1 / 0 overrides.
    """
    override = os.environ.get("RANGESIM_COHERENT_RAYS", "").strip().lower()
    if override:
        if override not in ("0", "1", "true", "false", "yes", "no"):
            raise RangesimError(f"RANGESIM_COHERENT_RAYS must be 1 or 0, not {override!r}",
                                source="RANGESIM_COHERENT_RAYS")
        return override in ("1", "true", "yes")
    flags = cpu_flags()
    return flags is None or "avx512f" in flags


@functools.lru_cache(maxsize=1)
def cpu_flags() -> frozenset[str] | None:
    """The CPU's feature flags (``avx2``, ``avx512f``, ...) from Linux ``/proc/cpuinfo``; None where
    that cannot be read."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return frozenset(line.split(":", 1)[-1].split())
    except OSError:
        pass
    return None


#: the oldest libLLVM Dr.Jit's CPU backend may use on a CPU with AVX-512: with Debian 12's
#: LLVM 15 and 16, a kernel taking a float maximum (``dr.maximum``; Mitsuba's ray casts have
#: them) makes LLVM abort the whole process ("LLVM ERROR: Cannot select: fmaximum", seen on
#: an AMD EPYC Zen 4 with its 16-lane AVX-512 code); LLVM 19 compiles it (17 and 18 were not
#: tried, so they are refused too: the rendered mode needs 19 on every CPU anyway,
#: :func:`rangesim.sensor.rendered.check_backend`)
MIN_LLVM_AVX512 = (19, 0, 0)


@functools.lru_cache(maxsize=1)
def llvm_problem() -> str | None:
    """Why Dr.Jit's CPU backend must not run here (a libLLVM known to abort the process on this
    CPU), or None. Checked before the first kernel, so the user reads a one-line refusal with
    the fix instead of an LLVM crash dump and a dead process."""
    import drjit as dr

    flags = cpu_flags()
    if flags is None or "avx512f" not in flags:
        return None
    version = tuple(dr.detail.llvm_version())
    if version >= MIN_LLVM_AVX512:
        return None
    found = ".".join(map(str, version))
    return (f"Dr.Jit found libLLVM {found}, which aborts on this AVX-512 CPU when it compiles Mitsuba's kernels; "
            f"install libLLVM {MIN_LLVM_AVX512[0]} or newer (Debian 12: apt-get install libllvm19; "
            "or run sh system-deps.sh) or point DRJIT_LIBLLVM_PATH at one")


#: the Mitsuba variants rangesim can run on (Dr.Jit's vectorised CPU and GPU backends)
JIT_PREFIXES = ("llvm_", "cuda_")


def mitsuba() -> ModuleType:
    """The ``mitsuba`` module with a variant set (choosing one on first use)."""
    import mitsuba as mi

    if mi.variant() is None:
        variant = choose_variant()
        # every scan casts its rays in one vectorised call: the JIT variants only
        usable = [v for v in mi.variants() if v.startswith(JIT_PREFIXES)]
        if variant not in mi.variants():
            raise RangesimError(f"unknown Mitsuba variant {variant!r}; available: {', '.join(usable)}",
                                source="RANGESIM_VARIANT")
        if not variant.startswith(JIT_PREFIXES):
            raise RangesimError(f"Mitsuba variant {variant!r} traces one ray at a time; rangesim casts all rays in "
                                f"one vectorised call and needs one of {', '.join(usable)}",
                                source="RANGESIM_VARIANT")
        try:
            mi.set_variant(variant)
        except Exception as exc:  # e.g. cuda requested without a GPU
            raise RangesimError(f"cannot use Mitsuba variant {variant!r}: {exc}") from exc
    if mi.variant().startswith("llvm"):
        problem = llvm_problem()
        if problem is not None:
            raise RangesimError(problem, source="libLLVM")
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
