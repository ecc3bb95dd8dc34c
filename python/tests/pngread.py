"""A small PNG decoder in pure Python (zlib and the five row filters of the PNG specification), independent of the
decoder abysslight uses, to read what the command writes."""

import struct
import zlib

import numpy as np


def _paeth(a: int, b: int, c: int) -> int:
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    if pa <= pb and pa <= pc:
        return a
    return b if pb <= pc else c


def read_png(path) -> np.ndarray:
    """An 8- or 16-bit grey or RGB PNG (not interlaced) as an HxW or HxWx3 uint8/uint16 array."""
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path}: not a PNG"
    pos, idat, header = 8, [], None
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos : pos + 4])
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + n]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        pos += 12 + n
    width, height, depth, colour, _, _, interlace = header
    channels = {0: 1, 2: 3}[colour]
    assert depth in (8, 16) and interlace == 0, f"{path}: unsupported PNG"
    bpp = channels * depth // 8
    stride = width * bpp
    raw = zlib.decompress(b"".join(idat))
    out = bytearray(height * stride)
    prev = bytearray(stride)
    for y in range(height):
        filt = raw[y * (stride + 1)]
        row = bytearray(raw[y * (stride + 1) + 1 : (y + 1) * (stride + 1)])
        for x in range(stride):
            a = row[x - bpp] if x >= bpp else 0
            b = prev[x]
            c = prev[x - bpp] if x >= bpp else 0
            if filt == 1:
                row[x] = (row[x] + a) & 255
            elif filt == 2:
                row[x] = (row[x] + b) & 255
            elif filt == 3:
                row[x] = (row[x] + (a + b) // 2) & 255
            elif filt == 4:
                row[x] = (row[x] + _paeth(a, b, c)) & 255
        out[y * stride : (y + 1) * stride] = row
        prev = row
    dtype = np.dtype(">u2") if depth == 16 else np.uint8
    arr = np.frombuffer(bytes(out), dtype=dtype).astype(np.uint16 if depth == 16 else np.uint8)
    shape = (height, width) if channels == 1 else (height, width, channels)
    return arr.reshape(shape)
