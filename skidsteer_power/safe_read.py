"""Reading files that may be anything: only regular files, and never more than a hard byte cap.

A path given as a state file or a bag can name a FIFO (``open`` blocks until a writer comes, so a
reader hangs, SIGTERM included), a character device (``/dev/zero`` reports size 0 and reads forever:
3.7 GB in 10 s through a size check that trusted ``st_size``), a socket or a directory (issue 34
item 13). :func:`open_regular` opens with ``O_NONBLOCK`` (a FIFO's open returns at once) and refuses
whatever ``fstat`` does not call a regular file; :func:`read_capped` then reads at most a declared
number of bytes whatever the file says its size is.
"""

from __future__ import annotations

import fcntl
import os
import stat
from pathlib import Path

from skidsteer_power.errors import InputError

_KINDS = (
    (stat.S_ISFIFO, 'a FIFO'),
    (stat.S_ISCHR, 'a character device'),
    (stat.S_ISBLK, 'a block device'),
    (stat.S_ISSOCK, 'a socket'),
    (stat.S_ISDIR, 'a directory'),
)


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), 'not a regular file')


def open_regular(path: str | os.PathLike[str], what: str = 'file') -> int:
    """A read-only file descriptor of ``path`` (blocking mode), or InputError if it is not a regular
    file (FIFO, device, socket, directory) or cannot be opened. The caller closes it."""
    source = Path(path)
    flags = os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC
    try:
        fd = os.open(source, flags)
    except OSError as err:
        raise InputError(f'{what} {source}: cannot open ({err.strerror or err})') from err
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise InputError(f'{what} {source} is {_kind(mode)}, not a regular file: refused')
        fcntl.fcntl(fd, fcntl.F_SETFL, fcntl.fcntl(fd, fcntl.F_GETFL) & ~os.O_NONBLOCK)
    except BaseException:
        os.close(fd)
        raise
    return fd


def check_regular(path: str | os.PathLike[str], what: str = 'file') -> None:
    """InputError unless ``path`` is a regular file that can be opened for reading."""
    os.close(open_regular(path, what))


def read_capped(path: str | os.PathLike[str], max_bytes: int, what: str = 'file') -> bytes:
    """The bytes of the regular file ``path``; InputError if it holds more than ``max_bytes``
    (counted while reading, not taken from ``st_size``) or is not a regular file."""
    fd = open_regular(path, what)
    chunks: list[bytes] = []
    total = 0
    try:
        while True:
            chunk = os.read(fd, min(1 << 20, max_bytes + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
            if total > max_bytes:
                raise InputError(f'{what} {path} is larger than {max_bytes:,} bytes: refused')
    except OSError as err:
        raise InputError(f'{what} {path}: cannot read ({err.strerror or err})') from err
    finally:
        os.close(fd)
    return b''.join(chunks)
