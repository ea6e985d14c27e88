"""The bytes of a capture as the scanner walks them: a window of the file at a time.

Two sources, one interface (:class:`Source`), and the scanner walks either the same way:

* :class:`MappedSource` maps a regular file a window at a time (``mmap``, read-only,
  ``MADV_WILLNEED`` so that a file not in the page cache is read ahead; made through libc,
  so that the C scanner gets the window's address without numpy), so that the C
  scanner reads the record headers, the EtherCAT and datagram headers and the WKCs in
  place and no payload byte is ever copied; the window is unmapped before the next one
  is mapped, so that the file's pages do not pile up in the process (RSS stays about one
  window however large the file). ``MAP_POPULATE`` was measured slower than letting the
  scanner fault pages in (the kernel maps 16 pages a fault): 32 ms against 18 ms to map
  and touch a 350 MB file. Mapping the next window ahead (populated) and unmapping the
  last one on other threads was slower too (0.44-0.54 s against 0.40 s on a 2 M-frame
  LOLA capture): the threads contend for the process's memory map lock, and an unmap in
  a process running on two cores costs TLB shootdowns on the other.
* :class:`ChunkedSource` reads the file in bounded chunks into one reusable buffer: pipes,
  ``/dev/stdin``, other files that are not regular, and the Python engine (which copies
  its buffer to ``bytes`` anyway).

A mapped file that shrinks while it is read (a capture being rotated or truncated):
reading a page past its new end raises SIGBUS, which would end the process. The C
scanner catches it (``lolacli_scan`` in ``_cscan.c``: a SIGBUS handler that jumps back
to the scan call when, and only when, the fault happened in its guarded walk) and
returns :data:`~lolacli.capture.scan.ST_FAULT` with the position of the record it was
reading (it reads one byte of each page of a record before counting it, so that the
fault comes before any counter changed). The bytes between the new end and the end of
its page read as zeros without a fault, so the analysis does not go on from there: a
pass that faulted, or that ends on a file now shorter than what it mapped
(:meth:`MappedSource.shrank`), is done again from the start through read()
(``analyze_file``), and the result is the one the read path gives for the file as it
is then, as before mapping. Every other read of a mapped file's bytes (mailbox and
configuration data, pcapng section and interface blocks, the record stopped at) goes
through ``os.pread`` (:meth:`Source.bytes_at`), which cannot fault. Checking the size
before each window would leave a gap between the check and the read; ``MAP_POPULATE``
would not keep pages that a truncation removes either.
"""

from __future__ import annotations

import ctypes
import mmap
import os
import stat
from functools import lru_cache
from pathlib import Path
from types import TracebackType
from typing import Any, BinaryIO

#: read path: bytes per read() into the reusable buffer
CHUNK_BYTES = 8 * 1024 * 1024
#: mapped path: bytes mapped at a time (a multiple of the allocation granularity)
WINDOW_BYTES = 64 * 1024 * 1024
_GRAN = mmap.ALLOCATIONGRANULARITY


class Mapping:
    """A read-only shared mapping of ``size`` bytes of a file at ``address`` (libc
    ``mmap``): what the C scanner walks. Python reads its bytes by ``os.pread`` only."""

    def __init__(self, fd: int, length: int, offset: int) -> None:
        libc = _libc()
        address = libc.mmap(None, length, mmap.PROT_READ, mmap.MAP_SHARED, fd, offset)
        if address is None or address == _MAP_FAILED:
            err = ctypes.get_errno()
            raise OSError(err, os.strerror(err))
        self.address: int = address
        self.size = length
        if hasattr(mmap, "MADV_WILLNEED"):  # a file not in the page cache: read ahead
            libc.madvise(address, length, mmap.MADV_WILLNEED)

    def __len__(self) -> int:
        return self.size

    def close(self) -> None:
        if self.size:
            _libc().munmap(self.address, self.size)
            self.address, self.size = 0, 0


_MAP_FAILED = ctypes.c_void_p(-1).value


@lru_cache(maxsize=1)
def _libc() -> ctypes.CDLL:
    libc = ctypes.CDLL(None, use_errno=True)
    libc.mmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int, ctypes.c_int,
                          ctypes.c_int, ctypes.c_int64]
    libc.mmap.restype = ctypes.c_void_p
    libc.munmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t]
    libc.munmap.restype = ctypes.c_int
    libc.madvise.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
    libc.madvise.restype = ctypes.c_int
    return libc


class Source:
    """``buf[:end]`` holds the file's bytes from offset ``base``; ``eof`` when ``end`` is
    the end of the file (a :class:`bytearray` read into, or a :class:`Mapping`). Owns the
    open file ``f`` and closes it."""

    def __init__(self, f: BinaryIO) -> None:
        self.f = f
        self.buf: bytearray | Mapping = bytearray()
        self.base = 0
        self.end = 0
        self.eof = False

    def advance(self, pos: int) -> int:
        """Keep the bytes from ``pos`` on, bring the next ones in; returns where ``pos``
        is now in :attr:`buf`. A record of any size fits eventually: a window that makes
        no progress grows."""
        raise NotImplementedError

    def bytes_at(self, i: int, n: int) -> bytes:
        """``n`` bytes at ``buf[i]`` (fewer when they are past the end, or when a mapped
        file shrank)."""
        raise NotImplementedError

    def close(self) -> None:
        self.f.close()

    def __enter__(self) -> Source:
        return self

    def __exit__(self, t: type[BaseException] | None, e: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


class ChunkedSource(Source):
    """The file read forward in chunks into one buffer (grown for a record larger than
    half of it)."""

    buf: bytearray

    def __init__(self, f: BinaryIO, chunk_bytes: int = CHUNK_BYTES) -> None:
        super().__init__(f)
        self.buf = bytearray(max(chunk_bytes, 1 << 16))
        self.end, self.eof = _fill(f, self.buf, 0)

    def advance(self, pos: int) -> int:
        tail = self.end - pos
        if tail * 2 > len(self.buf):
            grown = bytearray(len(self.buf) * 2)
            grown[:tail] = memoryview(self.buf)[pos : self.end]
            self.buf = grown
        else:
            self.buf[:tail] = self.buf[pos : self.end]
        self.base += pos
        self.end, self.eof = _fill(self.f, self.buf, tail)
        return 0

    def bytes_at(self, i: int, n: int) -> bytes:
        return bytes(memoryview(self.buf)[i : min(i + n, self.end)])


class MappedSource(Source):
    """A regular file mapped a window at a time (see the module docstring)."""

    def __init__(self, f: BinaryIO, window_bytes: int = WINDOW_BYTES) -> None:
        super().__init__(f)
        self._fd = f.fileno()
        self._window = max(-(-window_bytes // _GRAN) * _GRAN, _GRAN)
        self._map: Mapping | None = None
        self._mapped_to = 0
        self._open(0, self._window)

    def _open(self, offset: int, length: int) -> None:
        self._release()
        size = os.fstat(self._fd).st_size
        length = min(length, size - offset)
        self.base = offset
        if length <= 0:
            self.buf, self.end, self.eof = bytearray(), 0, True
            return
        self._map = self.buf = Mapping(self._fd, length, offset)
        self.end, self.eof = length, offset + length >= size
        self._mapped_to = max(self._mapped_to, offset + length)

    def _release(self) -> None:
        self.buf = bytearray()
        if self._map is not None:
            self._map.close()
            self._map = None

    def advance(self, pos: int) -> int:
        at = self.base + pos
        offset = at - at % _GRAN
        length = self._window
        if offset == self.base and self.end >= length:  # a record longer than the window
            length = self.end * 2
        self._open(offset, length)
        return at - offset

    def bytes_at(self, i: int, n: int) -> bytes:
        return os.pread(self._fd, max(0, min(n, self.end - i)), self.base + i)

    def shrank(self) -> bool:
        """Whether the file is now shorter than what was mapped of it."""
        return os.fstat(self._fd).st_size < self._mapped_to

    def close(self) -> None:
        try:
            self._release()
        finally:
            super().close()


def open_source(path: str | Path, chunk_bytes: int | None = None, *,
                mapped: bool = True) -> Source:
    """The file's bytes: mapped when ``mapped`` and the file is a regular, non-empty file
    that maps, else read in chunks. ``chunk_bytes`` is the read chunk or the mapped
    window (defaults :data:`CHUNK_BYTES`, :data:`WINDOW_BYTES`)."""
    f = open(path, "rb")  # noqa: SIM115 (the source closes it)
    try:
        info = os.fstat(f.fileno())
        if mapped and stat.S_ISREG(info.st_mode) and info.st_size > 0:
            try:
                return MappedSource(f, chunk_bytes or WINDOW_BYTES)
            except (OSError, ValueError):  # a file system that does not map: read it
                f.seek(0)
        return ChunkedSource(f, chunk_bytes or CHUNK_BYTES)
    except BaseException:
        f.close()
        raise


def _fill(f: Any, buf: bytearray, start: int) -> tuple[int, bool]:
    """Read into ``buf[start:]``; returns (end, eof)."""
    view = memoryview(buf)[start:]
    got = 0
    while got < len(view):
        n = f.readinto(view[got:])
        if not n:
            return start + got, True
        got += n
    return start + got, False
