"""DES 70/10 client and transport against the simulator on a pty (the robot's pyserial path)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from typing import TypedDict, Unpack

import pytest

from skidsteer_power.cli.main import main as cli_main
from skidsteer_power.des.client import DesAmplifier
from skidsteer_power.des.errors import (
    DesCrcError,
    DesError,
    DesFault,
    DesLinkError,
    DesNak,
    DesPortError,
    DesTimeout,
)
from skidsteer_power.des.protocol import DesConfig, DesErrorFlags, OpCode, Param, Status
from skidsteer_power.des.simulator import SIM_VERSION, Fault, SimulatedDes
from skidsteer_power.des.transport import DesLink, LinkTiming
from skidsteer_power.errors import InputError

# Generous deadlines: CI machines are loaded; the fault tests choose their own.
TIMING = LinkTiming(ack_timeout_s=0.3, reply_timeout_s=0.3, retries=2)


@pytest.fixture
def sim() -> Iterator[SimulatedDes]:
    with SimulatedDes(38400) as simulator:
        yield simulator


@pytest.fixture
def amp(sim: SimulatedDes) -> Iterator[DesAmplifier]:
    with DesAmplifier.open(sim.port, 38400, timing=TIMING) as amplifier:
        yield amplifier


class Timing(TypedDict, total=False):
    """Keyword arguments of LinkTiming."""

    ack_timeout_s: float
    reply_timeout_s: float
    slack_s: float
    retries: int


def open_amp(sim: SimulatedDes, **timing: Unpack[Timing]) -> DesAmplifier:
    return DesAmplifier.open(sim.port, sim.baudrate, config=sim.config, timing=LinkTiming(**timing))


def wait_for(predicate: Callable[[], object], timeout_s: float = 5.0, period_s: float = 0.02) -> bool:
    """Poll ``predicate`` until true or the deadline (a wait, not a timing assertion)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(period_s)
    return bool(predicate())


# -- every command ------------------------------------------------------------------------------


def test_exception_tree() -> None:
    assert issubclass(DesFault, DesError) and issubclass(DesLinkError, DesError)
    assert not issubclass(DesFault, DesLinkError)
    for cls in (DesTimeout, DesNak, DesCrcError, DesPortError):
        assert issubclass(cls, DesLinkError)


def test_the_port_is_a_real_pty_behind_a_symlink(sim: SimulatedDes, amp: DesAmplifier) -> None:
    assert os.path.islink(sim.port)
    assert os.path.realpath(sim.port).startswith('/dev/pts/')
    assert amp.link.is_open


def test_read_version(amp: DesAmplifier) -> None:
    version = amp.read_version()
    assert (
        version.software,
        version.hardware,
        version.application_number,
        version.application_version,
    ) == SIM_VERSION


def test_status_after_power_up_and_enable(sim: SimulatedDes, amp: DesAmplifier) -> None:
    status = amp.read_status()
    assert Status.ENABLED not in status and status.power_stage == 'off'
    amp.enable()
    status = amp.read_status()
    assert Status.ENABLED in status and status.power_stage == 'on'
    amp.disable()
    assert Status.ENABLED not in amp.read_status()
    assert sim.commands_of(OpCode.ENABLE)[-1].words == (0,)


def test_set_velocity_and_read_it_back(sim: SimulatedDes, amp: DesAmplifier) -> None:
    amp.enable()
    amp.set_velocity(-1500)
    assert sim.speed_setpoint_rpm == -1500  # executed before the final acknowledge
    # Wait for the motor at rest on its set point, not for a reading inside a band: the mean speed
    # passes -1500 +- 10 rpm during the ramp (t ~ 0.17 s) while the instantaneous speed is already
    # about -1600 (the overshoot), and enters the band again after it (t ~ 0.34 s) while the current
    # still brakes (+60 mA); a read landing there (the phase of the reads shifts under load) failed.
    assert wait_for(sim.settled)
    mean, instantaneous = amp.read_velocity(), amp.read_velocity(instantaneous=True)
    assert mean.setpoint_rpm == instantaneous.setpoint_rpm == -1500
    assert abs(mean.actual_rpm + 1500) <= 2 and abs(instantaneous.actual_rpm + 1500) <= 2
    # driving backwards against friction needs negative current: at rest -(I_0 + b w / K_t) =
    # -(0.193 A + 1e-5 N m s/rad x 157.1 rad/s / 0.114 N m/A) = -207 mA (motor_model defaults)
    assert amp.read_current() < 0


def test_set_current_and_read_it(sim: SimulatedDes, amp: DesAmplifier) -> None:
    amp.enable()
    amp.set_current(800)
    assert sim.current_mode and sim.current_setpoint_ma == 800
    assert wait_for(lambda: abs(amp.read_current() - 800) <= 40)
    assert abs(amp.read_current(instantaneous=True) - 800) <= 40
    assert amp.read_velocity().actual_rpm > 0


def test_current_through_op_code_0x29(sim: SimulatedDes) -> None:
    config = DesConfig(current_source='is_must')
    with DesAmplifier.open(sim.port, 38400, config=config, timing=TIMING) as amp:
        amp.enable()
        amp.set_current(500)
        assert wait_for(lambda: abs(amp.read_current() - 500) <= 30)
    assert sim.commands_of(OpCode.READ_CURRENT_IS_MUST)


def test_stop_motion_toggles(sim: SimulatedDes, amp: DesAmplifier) -> None:
    amp.enable()
    amp.set_velocity(1000)
    amp.stop_motion()
    assert Status.BRAKING in amp.read_status()
    assert amp.read_velocity().setpoint_rpm == 0
    amp.stop_motion()
    assert amp.read_velocity().setpoint_rpm == 1000


def test_set_point_out_of_int16_range(amp: DesAmplifier) -> None:
    with pytest.raises(InputError, match='int16'):
        amp.set_velocity(40000)
    with pytest.raises(InputError, match='int16'):
        amp.set_current(-40000)


def test_parameters_read_set_save_reset(sim: SimulatedDes, amp: DesAmplifier) -> None:
    assert amp.read_parameter(Param.ENCODER_RESOLUTION) == 2048  # ch. 7.1.2: 2048 pulses per turn
    amp.set_parameter(Param.MAX_SPEED_RPM, 5000)
    assert amp.read_parameter(Param.MAX_SPEED_RPM) == 5000
    amp.reset_parameters()  # EEPROM -> RAM: the change is gone
    assert amp.read_parameter(Param.MAX_SPEED_RPM) == 10000
    amp.set_parameter(Param.MAX_SPEED_RPM, 6000)
    amp.save_parameters()
    amp.reset_parameters()
    assert amp.read_parameter(Param.MAX_SPEED_RPM) == 6000
    assert sim.eeprom[Param.MAX_SPEED_RPM] == 6000


@pytest.mark.parametrize('low_first', [True, False])
def test_lword_parameter_round_trip(low_first: bool) -> None:
    config = DesConfig(lword_low_word_first=low_first)
    with (
        SimulatedDes(38400, config=config) as sim,
        DesAmplifier.open(sim.port, config=config, timing=TIMING) as amp,
    ):
        amp.set_parameter(Param.SPEED_P, 70000, lword=True)
        assert sim.params[Param.SPEED_P] == 70000
        assert amp.read_parameter(Param.SPEED_P, lword=True) == 70000


def test_unknown_parameter_is_refused_with_nak(amp: DesAmplifier) -> None:
    with pytest.raises(DesNak, match='refused'):
        amp.read_parameter(99)


def test_encoder_counter_advances_with_the_motor(sim: SimulatedDes, amp: DesAmplifier) -> None:
    amp.enable()
    amp.set_velocity(60)  # 1 rev/s = 8192 quadrature counts/s (2048 lines x 4)
    assert wait_for(lambda: abs(amp.read_velocity().actual_rpm - 60) <= 2)
    first = amp.read_encoder_counter()
    time.sleep(0.2)
    second = amp.read_encoder_counter()
    moved = (second - first) % 65536
    assert 0 < moved < 8192  # forward, less than one turn in well under a second


def test_errors_read_clear_and_fault_exception(sim: SimulatedDes, amp: DesAmplifier) -> None:
    amp.enable()
    assert amp.read_errors() == DesErrorFlags(0)
    sim.raise_error(DesErrorFlags.OVER_CURRENT)
    status = amp.read_status()
    assert Status.ERROR in status and status.power_stage == 'off'
    with pytest.raises(DesFault, match='OVER_CURRENT') as info:
        amp.raise_for_errors()
    assert DesErrorFlags.OVER_CURRENT in info.value.errors
    amp.clear_errors()
    assert amp.read_errors() == DesErrorFlags(0)
    amp.raise_for_errors()


def test_reset_restores_power_up_state(sim: SimulatedDes, amp: DesAmplifier) -> None:
    amp.enable()
    amp.set_velocity(500)
    amp.reset()
    assert Status.ENABLED not in amp.read_status()
    assert amp.read_velocity().setpoint_rpm == 0


# -- every fault kind ---------------------------------------------------------------------------


def test_dropped_command_is_retried(sim: SimulatedDes) -> None:
    with open_amp(sim, ack_timeout_s=0.1, retries=1) as amp:
        sim.inject(Fault.DROP)
        assert amp.read_status() is not None
        assert amp.link.stats.timeouts == 1 and amp.link.stats.retries == 1


def test_dropped_command_without_retries_times_out(sim: SimulatedDes) -> None:
    with open_amp(sim, ack_timeout_s=0.1, retries=0) as amp:
        sim.inject(Fault.DROP)
        with pytest.raises(DesTimeout, match='no acknowledge of op code 0x01'):
            amp.read_status()
        assert amp.read_status() is not None  # the next one goes through


def test_nak_is_retried_or_raised(sim: SimulatedDes) -> None:
    with open_amp(sim, retries=1) as amp:
        sim.inject(Fault.NAK)
        amp.read_errors()
        assert amp.link.stats.naks == 1
    with open_amp(sim, retries=0) as amp:
        sim.inject(Fault.NAK)
        with pytest.raises(DesNak, match='refused op code 0x02'):
            amp.read_errors()


def test_corrupt_reply_is_refused_and_repeated(sim: SimulatedDes) -> None:
    with open_amp(sim, retries=0, ack_timeout_s=0.3, reply_timeout_s=0.3) as amp:
        sim.inject(Fault.CORRUPT_CRC)
        assert amp.read_parameter(Param.POLE_PAIRS) == 2  # Appendix B line 29: 2 pole pairs
        assert amp.link.stats.crc_errors == 1


def test_corrupt_reply_without_repeat_raises_crc_error() -> None:
    config = DesConfig(des_repeats_reply_after_nak=False)
    with SimulatedDes(38400, config=config) as sim:
        with DesAmplifier.open(sim.port, config=config, timing=LinkTiming(retries=0)) as amp:
            sim.inject(Fault.CORRUPT_CRC)
            with pytest.raises(DesCrcError, match='CRC mismatch'):
                amp.read_status()
        with DesAmplifier.open(sim.port, config=config, timing=LinkTiming(retries=1)) as amp:
            sim.inject(Fault.CORRUPT_CRC)
            assert amp.read_status() is not None


def test_short_delay_is_tolerated_long_delay_times_out(sim: SimulatedDes) -> None:
    with open_amp(sim, ack_timeout_s=0.3, reply_timeout_s=0.3, retries=0) as amp:
        sim.inject(Fault.DELAY, delay_s=0.05)
        amp.read_status()
        sim.inject(Fault.DELAY, delay_s=0.6)
        with pytest.raises(DesTimeout):
            amp.read_status()
        port = amp.link._serial  # the host's end of the pty
        assert port is not None
        assert wait_for(lambda: port.in_waiting >= 1)  # the late answer arrived; the next exchange flushes it
        assert amp.read_errors() == DesErrorFlags(0)
        assert amp.link.stats.flushed_bytes >= 1


def test_silent_amplifier_times_out_until_it_answers_again(sim: SimulatedDes) -> None:
    with open_amp(sim, ack_timeout_s=0.05, retries=1) as amp:
        sim.inject(Fault.SILENT, count=-1)
        with pytest.raises(DesTimeout):
            amp.read_status()
        assert amp.link.stats.failures == 1
        sim.clear_faults()
        assert amp.read_status() is not None


def test_closed_port_raises_port_error_and_reopens(sim: SimulatedDes) -> None:
    with open_amp(sim, ack_timeout_s=0.3, reply_timeout_s=0.3) as amp:
        amp.read_status()
        sim.close_port()
        with pytest.raises(DesPortError, match='lost'):
            amp.read_status()
        assert not amp.link.is_open
        with pytest.raises(DesPortError, match='cannot open'):
            amp.link.open()
        sim.reopen_port()
        amp.link.open()
        assert amp.read_version().software == SIM_VERSION[0]


def test_garbage_on_the_line_is_flushed(sim: SimulatedDes) -> None:
    with open_amp(sim, ack_timeout_s=0.3, reply_timeout_s=0.3) as amp:
        sim.send_raw(b'\x13\x37garbage')  # bytes the host did not ask for
        time.sleep(0.05)
        assert amp.read_errors() == DesErrorFlags(0)
        assert amp.link.stats.flushed_bytes >= 9


def test_unopened_link_refuses() -> None:
    link = DesLink('/nonexistent/des')
    with pytest.raises(DesPortError, match='not open'):
        link.transact(OpCode.READ_SYS_STATUS, reply_words=1)
    with pytest.raises(DesPortError, match='cannot open'):
        link.open()


# -- CLI ----------------------------------------------------------------------------------------


def test_cli_probe_json(sim: SimulatedDes, capsys: pytest.CaptureFixture[str]) -> None:
    sim.enabled = True
    sim.speed_setpoint_rpm = 1200
    assert wait_for(lambda: abs(sim.speed_rpm - 1200) < 5)
    assert cli_main(['des', 'probe', '--port', sim.port, '--json']) == 0
    out = json.loads(capsys.readouterr().out)
    assert out['software_version'] == SIM_VERSION[0]
    assert Status.ENABLED in Status(out['status'])
    assert out['errors'] == 0
    assert out['velocity_setpoint_rpm'] == 1200
    assert abs(out['velocity_rpm'] - 1200) <= 10
    assert out['current_ma'] > 0


def test_cli_probe_bad_port_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(['des', 'probe', '--port', '/nonexistent/des', '--json']) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'cannot open DES port' in err


def test_cli_probe_silent_amplifier_is_one_line(
    sim: SimulatedDes, capsys: pytest.CaptureFixture[str]
) -> None:
    sim.inject(Fault.SILENT, count=-1)
    assert cli_main(['des', 'probe', '--port', sim.port, '--timeout', '0.05']) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'no acknowledge' in err


def test_cli_des_sim_prints_ports_and_stops_on_sigint() -> None:
    proc = subprocess.Popen(
        [sys.executable, '-m', 'skidsteer_power.cli.main', 'des-sim', '--count', '2', '--json'],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        lines: list[str] = []
        assert proc.stdout is not None
        while not lines or lines[-1] != '}\n':
            lines.append(proc.stdout.readline())
        ports = json.loads(''.join(lines))
        for side in ('left', 'right'):
            with DesAmplifier.open(ports[side], timing=TIMING) as amp:
                assert amp.read_version().software == SIM_VERSION[0]
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=10) == 0
        assert not os.path.exists(ports['left'])
    finally:
        proc.kill()
        proc.wait()
