"""LZF (liblzf) decompression, as used by PCD ``binary_compressed`` files.

No maintained, pre-built LZF package is a dependency of the project, so the decoder is
written here. An LZF stream is a sequence of tokens, each starting with a control byte
``c``:

* ``c < 32``: a literal run; the next ``c + 1`` input bytes are copied to the output.
* ``c >= 32``: a back reference of length ``(c >> 5) + 2`` (when ``c >> 5 == 7`` one more
  byte is added to the length), copying from ``((c & 31) << 8 | next byte) + 1`` bytes
  back in the output; source and destination may overlap (a repeated pattern).

Tokens depend on the output written before them, so decoding is a sequential loop; each
token is one slice copy. A 640 x 480 mOSD frame (2.0 MB compressed, 6.1 MB out, 610 k
tokens) decodes in about 0.2 s. Attempts to vectorise the reference resolution with NumPy
(pointer jumping) were slower.
"""
from __future__ import annotations

import numpy as np

__all__ = ["LZFError", "lzf_decompress", "lzf_store"]

#: most output bytes per input byte an LZF stream can give (264 from a 3-byte back reference)
MAX_EXPANSION = 88


class LZFError(ValueError):
    """A corrupt or truncated LZF stream (callers add the file name)."""


def lzf_decompress(data: bytes | bytearray | memoryview, size: int) -> bytes:
    """Decompress an LZF stream whose decompressed length is known.

    Parameters
    ----------
    data : bytes-like
        The compressed stream (exactly the compressed bytes, nothing after them).
    size : int
        The expected decompressed length in bytes.

    Returns
    -------
    bytes
        ``size`` bytes.

    Raises
    ------
    LZFError
        If the stream is truncated, refers before the start of the output, or does not
        decode to exactly ``size`` bytes.
    """
    data = bytes(data)
    n = len(data)
    # a back reference's 3 bytes give at most 264 (2 + 7 + 255) bytes out, a literal's c + 2
    # bytes give c + 1: a size beyond 88 bytes per input byte cannot come out of this stream
    # (and would be allocated before the first token: a header's 10**12 raised MemoryError)
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or not 0 <= size <= MAX_EXPANSION * n:
        raise LZFError(f"expected {size!r:.30} decompressed bytes from {n:,} compressed ones: at most "
                       f"{MAX_EXPANSION} per compressed byte fit an LZF stream")
    out = bytearray(int(size))
    ip = op = 0
    try:
        while ip < n:
            ctrl = data[ip]
            ip += 1
            if ctrl < 32:  # literal run
                end = ip + ctrl + 1
                oe = op + ctrl + 1
                if end > n:
                    raise LZFError(f"literal run at byte {ip - 1} runs past the end of the stream")
                if oe > size:
                    raise LZFError(f"decodes to more than the declared {size} bytes")
                out[op:oe] = data[ip:end]
                ip, op = end, oe
            else:  # back reference
                length = (ctrl >> 5) + 2
                if length == 9:
                    length += data[ip]
                    ip += 1
                ref = op - ((ctrl & 31) << 8) - data[ip] - 1
                ip += 1
                oe = op + length
                if ref < 0:
                    raise LZFError(f"back reference at byte {ip} points before the start of the output")
                if oe > size:
                    raise LZFError(f"decodes to more than the declared {size} bytes")
                if ref + length <= op:
                    out[op:oe] = out[ref:ref + length]
                else:  # overlapping: the last (op - ref) bytes repeat
                    period = op - ref
                    out[op:oe] = (out[ref:op] * (length // period + 1))[:length]
                op = oe
    except IndexError:  # a control byte's operand is missing
        raise LZFError("stream ends inside a token (truncated)") from None
    if op != size:
        raise LZFError(f"decodes to {op} bytes, expected {size}")
    return bytes(out)


def lzf_store(data: bytes | bytearray | memoryview) -> bytes:
    """Encode bytes as a valid LZF stream of literal runs only (no compression).

    Any LZF decoder (liblzf, PCL) reads it back; it is 1/32 larger than the input. Used
    to write PCD ``binary_compressed`` files without an LZF compressor.

    Parameters
    ----------
    data : bytes-like

    Returns
    -------
    bytes
    """
    buf = np.frombuffer(bytes(data), dtype=np.uint8)
    full, rest = divmod(buf.size, 32)
    blocks = np.empty((full, 33), dtype=np.uint8)
    blocks[:, 0] = 31  # a literal run of 32 bytes
    blocks[:, 1:] = buf[: full * 32].reshape(full, 32)
    tail = b"" if rest == 0 else bytes([rest - 1]) + buf[full * 32:].tobytes()
    return blocks.tobytes() + tail
