"""Render the parameter files, the typed parameter objects and the parameter tables from the nodes'
specs (module :mod:`skidsteer_power.nodes.param_spec`): config/des_driver.yaml, config/estimator.yaml,
skidsteer_power/nodes/parameters.py and the tables in the ``params NODE`` blocks of docs/INTERFACES.md
(markers: :mod:`skidsteer_power.doc_blocks`; ``python -m tools.docs_figures`` fills the same blocks with
the same tables).

    python -m skidsteer_power.nodes.param_files          # rewrite them from the specs
    python -m skidsteer_power.nodes.param_files --check  # exit 1 if a shipped file differs
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

from skidsteer_power.doc_blocks import replace_block
from skidsteer_power.nodes import des_driver, power_estimator
from skidsteer_power.nodes.param_spec import ParamSpec, render_parameters_module, render_table, render_yaml

ROOT = Path(__file__).resolve().parents[2]
DOC = Path('docs/INTERFACES.md')


class NodeParams(NamedTuple):
    node: str
    specs: Sequence[ParamSpec]
    yaml_file: Path  # relative to the source tree
    header: str
    class_name: str  # of its typed parameter object in PARAMETERS_MODULE


DES_DRIVER_HEADER = """\
# Default parameters of the des_driver node, rendered from its spec (PARAMETERS in
# skidsteer_power/nodes/des_driver.py) by `python -m skidsteer_power.nodes.param_files`; edit the spec.
# ROS 2 parameter-file format:
#   des_driver --ros-args --params-file config/des_driver.yaml
# The launch file passes it (then vehicle, left_port and right_port from its arguments); copy it and
# edit for your robot. test/test_param_spec.py checks that this file is the spec's rendering.
# cmd_vel is read best effort (matches reliable and best-effort publishers); to force reliable, add
#   qos_overrides:
#     /cmd_vel:
#       subscription:
#         reliability: reliable
"""

PARAMETERS_MODULE = Path('skidsteer_power/nodes/parameters.py')
PARAMETERS_HEADER = """\
The nodes' parameters as frozen, typed objects: one dataclass per node, a field per parameter (name,
type, default, description as in the node's PARAMETERS spec), filled by
:func:`skidsteer_power.nodes.param_spec.read_parameters` after each value's type, range and choices
are checked. Rendered from the specs by ``python -m skidsteer_power.nodes.param_files`` (``--check``
in CI): edit the spec, not this file.
"""

ESTIMATOR_HEADER = """\
# Default parameters of the power_estimator node, rendered from its spec (PARAMETERS in
# skidsteer_power/nodes/power_estimator.py) by `python -m skidsteer_power.nodes.param_files`; edit the
# spec. ROS 2 parameter-file format:
#   power_estimator --ros-args --params-file config/estimator.yaml
# test/test_param_spec.py checks that this file is the spec's rendering.
# Every publisher and subscription takes the standard QoS overrides, for example:
#   qos_overrides:
#     /joint_states:
#       subscription:
#         reliability: reliable
"""

NODES = (
    NodeParams(
        des_driver.NODE_NAME,
        des_driver.PARAMETERS,
        Path('config/des_driver.yaml'),
        DES_DRIVER_HEADER,
        'DesDriverParameters',
    ),
    NodeParams(
        power_estimator.NODE_NAME,
        power_estimator.PARAMETERS,
        Path('config/estimator.yaml'),
        ESTIMATOR_HEADER,
        'PowerEstimatorParameters',
    ),
)


def block_name(node: str) -> str:
    """The name of ``node``'s table block in the doc (``<!-- BEGIN generated: params NODE -->``)."""
    return f'params {node}'


def rendered(root: Path = ROOT) -> dict[Path, str]:
    """Every generated file (relative path) and the text it should have."""
    out = {entry.yaml_file: render_yaml(entry.node, entry.specs, entry.header) for entry in NODES}
    doc = (root / DOC).read_text(encoding='utf-8')
    for entry in NODES:
        doc = replace_block(doc, 'generated', block_name(entry.node), render_table(entry.specs), str(DOC))
    out[DOC] = doc
    classes = [
        (entry.class_name, f'The parameters of the {entry.node} node (its PARAMETERS).', entry.specs)
        for entry in NODES
    ]
    out[PARAMETERS_MODULE] = render_parameters_module(classes, PARAMETERS_HEADER)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--check', action='store_true', help='exit 1 if a shipped file differs')
    args = parser.parse_args(argv)
    stale = []
    for path, text in rendered().items():
        target = ROOT / path
        if not target.exists() or target.read_text(encoding='utf-8') != text:
            stale.append(str(path))
            if not args.check:
                target.write_text(text, encoding='utf-8')
    if args.check and stale:
        print(f'not the specs rendering: {", ".join(stale)}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
