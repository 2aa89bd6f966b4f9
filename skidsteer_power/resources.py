"""One place that finds the files this package ships: vehicles, terrains, powertrains, batteries,
joint_states mappings (joints), node parameters and the Foxglove layout
(``config/<kind>/<name>.<ext>``).

Where they are depends on how the package was installed:

1. a source checkout or an editable pip install: ``config/`` next to the ``skidsteer_power`` package
   (the files that belong to the code that runs win, even if another copy is installed);
2. ``colcon build`` (ament_python): ``<install>/share/skidsteer_power/config``, found through the
   ament index (``ament_index_python.get_package_share_directory``, which reads
   ``AMENT_PREFIX_PATH``, set by ``source install/setup.bash`` or colcon's ``local_setup``);
3. a plain ``pip install``: the same ``share/skidsteer_power`` tree under ``sys.prefix``
   (``setup.py`` ``data_files``).

Every loader resolves names here; a name that is not found raises ConfigError listing what IS
shipped and where it was looked for.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from skidsteer_power.errors import ConfigError

PACKAGE = 'skidsteer_power'
KINDS = ('vehicles', 'terrains', 'powertrains', 'batteries', 'joints', 'foxglove', '')
"""Sub-folders of ``config/`` that hold shipped files ('' = ``config/`` itself: node parameters)."""

_SOURCE_CONFIG = Path(__file__).resolve().parent.parent / 'config'


def ament_share_dir() -> Path | None:
    """``share/skidsteer_power`` from the ament index, or None (not installed by colcon, not sourced,
    or ament_index_python missing)."""
    try:
        from ament_index_python.packages import get_package_share_directory
    except ImportError:
        return None
    try:
        return Path(get_package_share_directory(PACKAGE))
    except (LookupError, OSError, ValueError):  # PackageNotFoundError is a KeyError; unset env: OSError
        return None


def config_roots() -> list[Path]:
    """Existing ``config/`` folders, most specific first (see the module docstring), no duplicates."""
    candidates = [_SOURCE_CONFIG]
    share = ament_share_dir()
    if share is not None:
        candidates.append(share / 'config')
    candidates.append(Path(sys.prefix) / 'share' / PACKAGE / 'config')
    roots: list[Path] = []
    for root in candidates:
        if root.is_dir() and all(not _same(root, r) for r in roots):
            roots.append(root)
    return roots


def _same(a: Path, b: Path) -> bool:
    try:
        return a.samefile(b)
    except OSError:
        return False


def config_dirs(kind: str) -> list[Path]:
    """Existing folders searched for shipped files of ``kind`` (one of :data:`KINDS`)."""
    if kind not in KINDS:
        raise ValueError(f'unknown resource kind {kind!r}; known: {KINDS}')  # a bug, not user input
    return [root / kind if kind else root for root in config_roots() if (root / kind).is_dir()]


def shipped(kind: str, suffixes: tuple[str, ...] = ('.yaml',)) -> dict[str, Path]:
    """Shipped files of ``kind``: name (file stem) -> path; the first folder of :func:`config_dirs`
    that has a name wins."""
    found: dict[str, Path] = {}
    for folder in config_dirs(kind):
        for path in sorted(folder.iterdir()):
            if path.suffix in suffixes and path.is_file():
                found.setdefault(path.stem, path)
    return found


def describe_shipped(kind: str, suffixes: tuple[str, ...] = ('.yaml',)) -> str:
    """'a, b, c' (or 'none: no config/<kind> folder in ...') for error messages."""
    names = sorted(shipped(kind, suffixes))
    if names:
        return ', '.join(names)
    searched = ', '.join(str(r) for r in config_roots()) or 'no config folder found'
    return f'none (searched {searched})'


def find(kind: str, name_or_path: str | os.PathLike[str], suffixes: tuple[str, ...] = ('.yaml',)) -> Path:
    """The file ``name_or_path`` (an existing path) or the shipped ``config/<kind>/<name><suffix>``.

    A bare name may carry its suffix. Raises ConfigError naming what is shipped.
    """
    text = os.fspath(name_or_path)
    candidate = Path(text).expanduser()
    if candidate.is_file():
        return candidate
    if os.sep not in text and '/' not in text:
        stem = Path(text).stem if Path(text).suffix in suffixes else text
        path = shipped(kind, suffixes).get(stem)
        if path is not None:
            return path
    label = kind[:-1] if kind.endswith('s') else (kind or 'parameter file')
    raise ConfigError(
        f'{label} {text!r}: no such file or shipped {label} (shipped: {describe_shipped(kind, suffixes)})'
    )


def params_file(name: str = 'estimator.yaml') -> Path:
    """A shipped node-parameter file (``config/<name>``), e.g. ``estimator.yaml``."""
    return find('', name)
