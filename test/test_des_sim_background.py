"""``skidsteer-power des-sim`` started as a background job of a script stops on SIGINT (issue 17).

A non-interactive shell starts ``cmd &`` with SIGINT ignored; Python then installs no
KeyboardInterrupt handler, and a command relying on it cannot be stopped with SIGINT. The child here
is started exactly so (SIGINT set to SIG_IGN before exec), as ``bash -c 'skidsteer-power des-sim &'``
would.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys


def test_des_sim_in_the_background_stops_on_sigint_and_removes_its_ports() -> None:
    proc = subprocess.Popen(
        [sys.executable, '-m', 'skidsteer_power.cli.main', 'des-sim', '--count', '2', '--json'],
        stdout=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN),
    )
    try:
        lines: list[str] = []
        assert proc.stdout is not None
        while not lines or lines[-1] != '}\n':
            line = proc.stdout.readline()
            assert line, 'des-sim exited before printing its ports'
            lines.append(line)
        ports = json.loads(''.join(lines))
        assert os.path.exists(ports['left']) and os.path.exists(ports['right'])
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=20) == 0
        assert not os.path.exists(ports['left']) and not os.path.exists(ports['right'])
    finally:
        proc.kill()
        proc.wait()
