"""package.xml declares what the installed code imports, and nothing it does not (issue 29).

The imports are read from the shipped sources (skidsteer_power/ and launch/) with ``ast``; a ROS
package imported there must be an exec_depend, a declared ROS package must be imported there, and the
Python libraries with a rosdep key (ros/rosdistro rosdep/python.yaml) must be declared by that key.
"""

from __future__ import annotations

import ast
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ROS_PACKAGES = {'rclpy', 'launch', 'launch_ros', 'ament_index_python', 'rcl_interfaces', 'builtin_interfaces'}
ROSDEP_KEYS = {  # import name -> rosdep key (rosdep/python.yaml)
    'numpy': 'python3-numpy',
    'scipy': 'python3-scipy',
    'yaml': 'python3-yaml',
    'serial': 'python3-serial',
    'matplotlib': 'python3-matplotlib',
    'rosbags': 'python3-rosbags-pip',
    'rich': 'python3-rich',
}
INDIRECT = {'builtin_interfaces'}  # comes with every message package (their own exec_depends)
# rcl_interfaces is imported directly (parameter descriptors, SetParametersResult): declared (issue 37)


def shipped_imports() -> set[str]:
    names: set[str] = set()
    for path in [*ROOT.joinpath('skidsteer_power').rglob('*.py'), *ROOT.joinpath('launch').glob('*.py')]:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names.update(alias.name.split('.')[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module.split('.')[0])
    return names


def depends(kind: str) -> set[str]:
    return {e.text or '' for e in ET.parse(ROOT / 'package.xml').getroot().iter(kind)}


def is_ros_package(name: str) -> bool:
    return name in ROS_PACKAGES or name.endswith(('_msgs', '_srvs'))


def test_every_imported_ros_package_and_library_is_declared() -> None:
    imported = shipped_imports()
    declared = depends('exec_depend')
    missing = {n for n in imported if is_ros_package(n) and n not in INDIRECT} - declared
    assert not missing, f'imported but not an exec_depend: {sorted(missing)}'
    keys = {ROSDEP_KEYS[n] for n in imported if n in ROSDEP_KEYS}
    assert keys <= declared, f'rosdep keys missing: {sorted(keys - declared)}'


def test_every_declared_ros_package_is_imported() -> None:
    imported = shipped_imports()
    unused = {d for d in depends('exec_depend') if not d.startswith('python3-') and d not in imported}
    assert not unused, f'declared but never imported by the shipped code: {sorted(unused)}'
