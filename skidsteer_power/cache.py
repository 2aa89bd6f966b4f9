"""Where derived tables are cached, and the digest of the code that computes them.

Power maps (:mod:`skidsteer_power.maps`) and the fast model's turning tables
(:mod:`skidsteer_power.models.fast`) are cached on disk under a key that holds everything that
changes their numbers: the vehicle and terrain fingerprints, the build options, and
:func:`physics_digest`, a hash of the WHOLE physics code (every module of ``terramechanics/``,
``models/``, ``maps/``, plus ``vehicle.py`` and ``interpolation.py``). Any edit there makes old
files miss the cache and get rebuilt; no version tag is bumped by hand.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import os
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import IO

CACHE_ENV = 'SKIDSTEER_POWER_CACHE'
_PACKAGE = Path(__file__).resolve().parent
PHYSICS_PACKAGES = ('terramechanics', 'models', 'maps')
PHYSICS_MODULES = ('vehicle.py', 'interpolation.py')


def default_cache_dir() -> Path:
    """$SKIDSTEER_POWER_CACHE, else ~/.cache/skidsteer_power."""
    env = os.environ.get(CACHE_ENV)
    return Path(env).expanduser() if env else Path.home() / '.cache' / 'skidsteer_power'


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike[str]) -> Iterator[IO[bytes]]:
    """A binary file to write ``path`` through: a uniquely named temporary file beside it, flushed to
    disk and renamed onto ``path`` when the block ends, deleted if it raises. Readers never see half
    a file, and processes writing the same path at once (Dask workers building one map) each rename
    a whole file of their own."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f'.{target.name}.', suffix='.tmp', dir=target.parent)
    try:
        with os.fdopen(fd, 'wb') as tmp:
            yield tmp
            tmp.flush()
            os.fsync(tmp.fileno())
        os.replace(tmp_name, target)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise


def physics_files() -> list[Path]:
    """Every source file whose code can change a map or table, in a fixed order."""
    files = [p for pkg in PHYSICS_PACKAGES for p in sorted((_PACKAGE / pkg).rglob('*.py'))]
    return files + [_PACKAGE / name for name in PHYSICS_MODULES]


@functools.lru_cache(maxsize=1)
def physics_digest() -> str:
    """12 hex digits of SHA-256 over the physics code (file names relative to the package + bytes)."""
    digest = hashlib.sha256()
    for path in physics_files():
        digest.update(str(path.relative_to(_PACKAGE)).encode('utf-8'))
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def options_digest(options: Mapping[str, object]) -> str:
    """8 hex digits identifying build options (floats by repr, so 2 and 2.0 hash alike)."""
    norm = {
        k: (repr(float(v)) if isinstance(v, (int, float)) and not isinstance(v, bool) else v)
        for k, v in options.items()
    }
    text = json.dumps(norm, sort_keys=True, default=str)
    return hashlib.sha256(text.encode('utf-8')).hexdigest()[:8]
