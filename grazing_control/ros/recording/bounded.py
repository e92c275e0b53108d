"""Reading a bag's bytes within a memory bound: the decompression budget and plain files only.

Shared by the analysis's reader (:mod:`grazing_control.recordings.reader`) and the
recovery of a killed recording (:mod:`.recovery`, ``grazing bag reindex``): a chunk's
declared uncompressed size is checked against what is left of the budget before anything
is allocated, and no decompressor ever produces more than the size a chunk declares;
decompression is streamed in pieces of at most PIECE bytes (:func:`pieces`: zstd through
a stream reader, lz4 with ``max_length``), so a reader that keeps only what it uses holds
one piece, not the chunk. A decompression bomb, honest about its size or lying, costs at
most the budget. A FIFO or device named like a bag's file is refused before it is opened
(opening a FIFO blocks until a writer appears).

The budget is also the memory bound of the analysis (docs/analysis.md, "Hostile files"):
the reader keeps the file and the records it inflated, and decoding a topic costs about
two bytes of numpy per byte of its records, so ``grazing analyze``, ``replay`` and
``identify`` stay below about 3.2 x MAX_BYTES plus the interpreter (measured: 0.81 GB
for a 5.4 MB file whose chunk inflates to 256 MiB of copies of a valid Pi2 record).
"""

from __future__ import annotations

import io
import os
import stat
from pathlib import Path

__all__ = ["BagReadError", "MAX_BYTES", "max_bytes", "regular_file", "pieces",
           "read_zstd", "decompress", "check_size"]


class BagReadError(ValueError):
    """The file is not an MCAP bag this reader can use (message says why)."""


#: The most bytes a bag may decompress to (chunks and whole-file compression together),
#: and the largest file read, unless the environment variable ``GRAZING_BAG_MAX_BYTES``
#: says otherwise. The package's bags hold about 2.3 kB per forcing period (bags/:
#: 2.9 MB for 1300 periods), so 256 MiB is over 100,000 periods; 1 GiB let a 5.4 MB file
#: take 2.1 to 3.4 GB and 30 s (issue 27).
MAX_BYTES = 256 << 20

#: Without ``GRAZING_BAG_MAX_BYTES``, a file may also inflate at most RATIO times its own
#: size (and always to MIN_BYTES). The package's bags inflate about 2x (bags/: 2.1 and
#: 2.2), rosbag2's zstd chunks of numeric messages 3-10x; a decompression bomb inflates
#: 1,000-30,000x (a 33 kB chunk to 1 GiB). Scanning a GiB of minimal records costs a
#: minute of Python, so the ratio, not only the absolute cap, is what keeps a bomb cheap.
RATIO = 50
MIN_BYTES = 64 << 20

#: The most bytes one step of a streamed decompression produces (:func:`pieces`).
PIECE = 1 << 24


def max_bytes(file_size: int | None = None) -> int:
    """The decompression budget of a file of ``file_size`` bytes.

    ``GRAZING_BAG_MAX_BYTES`` (a positive integer) when set, else
    ``min(MAX_BYTES, max(MIN_BYTES, RATIO * file_size))`` (MAX_BYTES when the size is
    not given).
    """
    text = os.environ.get("GRAZING_BAG_MAX_BYTES", "")
    if not text:
        if file_size is None:
            return MAX_BYTES
        return min(MAX_BYTES, max(MIN_BYTES, RATIO * int(file_size)))
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value <= 0:
        raise BagReadError(f"GRAZING_BAG_MAX_BYTES={text!r}: must be a positive integer "
                           "(bytes a bag may decompress to)")
    return value


def regular_file(path: Path) -> Path:
    """``path`` if it is a regular file (after links); a FIFO, device or folder is refused.

    Opening a FIFO blocks until a writer appears, so the type is checked before opening.
    """
    try:
        mode = os.stat(path).st_mode
    except OSError as exc:
        raise BagReadError(f"{path}: cannot be read ({exc.strerror})") from None
    if not stat.S_ISREG(mode):
        raise BagReadError(f"{path}: not a regular file (a FIFO, device or folder); "
                           "a bag's .mcap must be a plain file")
    return path


def pieces(kind: str, data: bytes, limit: int):
    """Yield the decompressed bytes of ``data`` (``kind`` "zstd" or "lz4"; every frame) in
    pieces of at most PIECE bytes, never more than ``limit + 1`` bytes in all.

    zstd through a stream reader, lz4 through a frame decompressor with ``max_length``:
    memory holds one piece whatever the declared or real size.
    """
    n = 0
    if kind == "zstd":
        import zstandard
        with zstandard.ZstdDecompressor().stream_reader(io.BytesIO(data),
                                                        read_across_frames=True) as r:
            while n <= limit:
                piece = r.read(min(limit + 1 - n, PIECE))
                if not piece:
                    return
                n += len(piece)
                yield piece
        return
    if kind != "lz4":
        raise BagReadError(f"unknown chunk compression {kind!r}")
    try:
        import lz4.frame
    except ImportError:
        raise BagReadError("an lz4-compressed chunk needs the lz4 package") from None
    d = lz4.frame.LZ4FrameDecompressor()
    rest = bytes(data)
    while n <= limit:
        piece = d.decompress(rest, max_length=min(limit + 1 - n, PIECE))
        rest = b""
        if piece:
            n += len(piece)
            yield piece
        if d.eof or (not piece and d.needs_input):
            return


def read_zstd(data: bytes, limit: int) -> bytearray:
    """Decompress every zstd frame of ``data``, never producing more than ``limit + 1`` bytes."""
    out = bytearray()
    for piece in pieces("zstd", data, limit):
        out += piece
    return out


def decompress(kind: str, data: bytes, size: int, budget: int) -> bytes:
    """A chunk's records: at most ``min(size, budget)`` bytes are ever produced."""
    if kind == "":
        return data
    check_size(size, budget)
    out = bytearray()
    for piece in pieces(kind, data, size):
        out += piece
    if len(out) > size:
        raise ValueError(f"more than the {size} bytes the chunk header says")
    return bytes(out)


def check_size(size: int, budget: int) -> None:
    """BagReadError if a chunk declaring ``size`` bytes exceeds what is left of the budget."""
    if size > budget:
        raise BagReadError(f"a chunk declares {size} uncompressed bytes, beyond the {budget} "
                           "bytes left of the file's decompression budget (a decompression "
                           "bomb?); GRAZING_BAG_MAX_BYTES raises the limit")
