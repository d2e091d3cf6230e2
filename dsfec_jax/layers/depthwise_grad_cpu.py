"""The depthwise conv's kernel gradient on the CPU as one compiled loop (numba), called from inside
the jitted program as an XLA custom call.

Why: XLA computes d w[i, j] = sum over images and pixels of tap (i, j) times g by writing out each
tap's shifted view of the input (a slice is a copy) and then reducing it, 9 activation-sized
copies per two images. The loop here reads the input and g once, in place (the timings against
XLA's form are in docs/profiler.md; `dsfec bench --train --compare kernels=plain` re-measures the step).

How it is called: jaxlib's CPU runtime takes only the typed FFI (`jax.ffi`), whose handler gets an
`XLA_FFI_CallFrame*` (jaxlib/include/xla/ffi/api/c_api.h, API 0.3). The handler below is a numba
`cfunc` that reads the frame's fields at their C offsets, answers XLA's metadata query with that
API version, and on the execute stage runs the loop on the argument and result buffers. The
frame layout is that of the pinned jaxlib; a test compares this path with XLA's formulation, so a
changed layout fails there, not silently.

Same values: the sums run in a fixed order (image, row, pixel), each row in the input dtype and
the rows accumulated in float64, so results are deterministic and differ from XLA's summation
order only by rounding. Other backends and dtypes use XLA's formulation (`conv.py`).
"""

from __future__ import annotations

import ctypes
import functools

import jax
import numba
import numpy as np
from numba import carray, cfunc, types
from numba.core import cgutils
from numba.extending import intrinsic

FFI_API_VERSION = (0, 3)  # XLA_FFI_API_MAJOR / MINOR of the header this reads
EXTENSION_METADATA = 1  # XLA_FFI_Extension_Metadata
STAGE_EXECUTE = 3  # XLA_FFI_ExecutionStage_EXECUTE
# 8-byte word offsets of the fields read (x86-64 / aarch64 layout of c_api.h's structs)
FRAME_EXTENSION, FRAME_STAGE, FRAME_ARGS, FRAME_RETS = 1, 4, 9, 14  # args / rets: the void** arrays
BUFFER_DATA, BUFFER_DIMS = 3, 5
METADATA_EXTENSION_PTR = 3  # XLA_FFI_Metadata_Extension.metadata
METADATA_VERSION_BYTES, METADATA_TRAITS_BYTES = 24, 32  # api_version.major_version; traits
SUPPORTED = (np.dtype(np.float32), np.dtype(np.float64))


@intrinsic
def _pointer(typingctx, address):
    """An int64 address as a void pointer (numba has no cast for it)."""

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], cgutils.voidptr_t)

    return types.voidptr(types.int64), codegen


@numba.njit(cache=True, nogil=True)
def kernel_grad_loop(x, g, k, stride, pad_h, pad_w, out):
    """out[i, j, c] = sum over b, h, w of x[b, h*s + i - pad_h, w*s + j - pad_w, c] * g[b, h, w, c]
    (taps outside x read 0)."""
    batch, height, width, channels = x.shape
    _, out_h, out_w, _ = g.shape
    total = np.zeros((k, k, channels), np.float64)
    row = np.zeros((k, k, channels), x.dtype)
    for b in range(batch):
        for h in range(out_h):
            row[:] = 0
            for w in range(out_w):
                for i in range(k):
                    r = h * stride + i - pad_h
                    if r < 0 or r >= height:
                        continue
                    for j in range(k):
                        q = w * stride + j - pad_w
                        if q < 0 or q >= width:
                            continue
                        for c in range(channels):
                            row[i, j, c] += x[b, r, q, c] * g[b, h, w, c]
            total += row
    out[:] = total


def _handler(dtype):
    """The FFI handler for one dtype: (x (B,H,W,C), g (B,Ho,Wo,C), [k, stride, pad_h, pad_w] int32)
    -> d w (k, k, C)."""

    # not cached on disk: numba's cache keys a function by its source, so the float32 and float64
    # closures would share one entry (the loop it calls is cached)
    @cfunc(types.voidptr(types.voidptr))
    def handler(call_frame):
        frame = carray(call_frame, (FRAME_RETS + 1,), np.int64)
        if frame[FRAME_EXTENSION] != 0:  # XLA asks which FFI version the handler was built for
            extension = carray(_pointer(frame[FRAME_EXTENSION]), (4,), np.int64)
            if (extension[1] & 0xFFFFFFFF) == EXTENSION_METADATA:
                metadata = extension[METADATA_EXTENSION_PTR]
                version = carray(_pointer(metadata + METADATA_VERSION_BYTES), (2,), np.int32)
                version[0] = FFI_API_VERSION[0]
                version[1] = FFI_API_VERSION[1]
                carray(_pointer(metadata + METADATA_TRAITS_BYTES), (1,), np.uint32)[0] = 0
            return _pointer(0)
        if (frame[FRAME_STAGE] & 0xFFFFFFFF) != STAGE_EXECUTE:
            return _pointer(0)
        args = carray(_pointer(frame[FRAME_ARGS]), (3,), np.int64)
        result = carray(_pointer(carray(_pointer(frame[FRAME_RETS]), (1,), np.int64)[0]), (6,), np.int64)
        bx = carray(_pointer(args[0]), (6,), np.int64)
        bg = carray(_pointer(args[1]), (6,), np.int64)
        xd = carray(_pointer(bx[BUFFER_DIMS]), (4,), np.int64)
        gd = carray(_pointer(bg[BUFFER_DIMS]), (4,), np.int64)
        settings = carray(_pointer(carray(_pointer(args[2]), (6,), np.int64)[BUFFER_DATA]), (4,), np.int32)
        k = settings[0]
        x = carray(_pointer(bx[BUFFER_DATA]), (xd[0], xd[1], xd[2], xd[3]), dtype)
        g = carray(_pointer(bg[BUFFER_DATA]), (gd[0], gd[1], gd[2], gd[3]), dtype)
        out = carray(_pointer(result[BUFFER_DATA]), (k, k, xd[3]), dtype)
        kernel_grad_loop(x, g, k, settings[1], settings[2], settings[3], out)
        return _pointer(0)

    return handler


@functools.cache
def _registered(dtype: np.dtype) -> tuple[str, object]:
    """Compile and register the handler for `dtype` once per process -> (its target name, the
    cfunc; kept here because XLA calls its address for the life of the process)."""
    handler = _handler(dtype.type)
    name = f"dsfec_depthwise_kernel_grad_{dtype.name}"
    capsule_new = ctypes.pythonapi.PyCapsule_New
    capsule_new.restype = ctypes.py_object
    capsule_new.argtypes = (ctypes.c_void_p, ctypes.c_char_p, ctypes.c_void_p)
    jax.ffi.register_ffi_target(name, capsule_new(handler.address, b"xla._CUSTOM_CALL_TARGET", None), platform="cpu")
    return name, handler


def supported(dtype) -> bool:
    return np.dtype(dtype) in SUPPORTED


def kernel_grad(x_BxHxWxC, g_BxHoxWoxC, k: int, stride: int, pad_h: int, pad_w: int):
    """d w (k, k, C) of a depthwise conv through the compiled loop (CPU only; `supported` dtypes)."""
    dtype = np.dtype(x_BxHxWxC.dtype)
    call = jax.ffi.ffi_call(_registered(dtype)[0], jax.ShapeDtypeStruct((k, k, x_BxHxWxC.shape[-1]), dtype),
                            vmap_method="sequential")
    settings = np.array([k, stride, pad_h, pad_w], np.int32)  # int32 in both of JAX's int modes
    return call(x_BxHxWxC, g_BxHoxWoxC.astype(dtype), settings)
