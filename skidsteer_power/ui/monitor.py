"""Energy-aware teleoperation view (the UI layer of ``energy_monitor``): what is shown and how it is
drawn with rich, how keys and case profiles become commands, and the CSV of what was shown. No ROS
and no terminal here, so all of it is testable; the rclpy shell is
:mod:`skidsteer_power.nodes.energy_monitor`.

Modelled on the test robot's own control software (chapter 7.1.3): a case mode (forward velocity and
yaw rate as inputs), a free mode (Up/Down/Left/Right keys drive the robot like a remote-controlled
vehicle), a display of the two motors' speeds and currents, a "Ready"/"Not Ready" link indicator, and
the data saved to a CSV file at the end. Added for energy-aware operation: predicted vs measured
power per side, the prediction as power_estimator corrects it online (issue 27: the figure its battery
forecast uses), battery gauge, time to empty and the traction warning (chapter 7.3.4: the robot got
stuck in tight turns on sand).
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from rich.console import Console, ConsoleOptions, Group, RenderableType, RenderResult
from rich.panel import Panel
from rich.table import Table
from rich.text import Text

from skidsteer_power.commands import Segment
from skidsteer_power.errors import InputError

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
STALE_AFTER_S = 1.0
"""A source silent for this long [s] is shown as stale (greyed, marked 'stale')."""
SOURCES = ('command', 'joint_states', 'summary', 'battery')
"""What the view shows comes from these; each may go stale on its own."""
SOURCE_NAMES = ('measured', 'predicted', 'none')

# --- keys (free mode) ---------------------------------------------------------------------------
KEY_SEQUENCES = {
    b'\x1b[A': 'up',
    b'\x1b[B': 'down',
    b'\x1b[C': 'right',
    b'\x1b[D': 'left',
    b'\x1bOA': 'up',
    b'\x1bOB': 'down',
    b'\x1bOC': 'right',
    b'\x1bOD': 'left',
    b' ': 'stop',
    b's': 'stop',
    b'q': 'quit',
    b'\x03': 'quit',  # Ctrl-C in raw mode
}


def decode_keys(buffer: bytes) -> tuple[list[str], bytes]:
    """Split raw terminal bytes into key names; returns (keys, bytes of an unfinished sequence).

    Unknown bytes are skipped, so a stray byte never stalls the decoder.
    """
    keys: list[str] = []
    i = 0
    while i < len(buffer):
        for seq, name in KEY_SEQUENCES.items():
            if buffer.startswith(seq, i):
                keys.append(name)
                i += len(seq)
                break
        else:
            rest = buffer[i:]
            if rest[:1] == b'\x1b' and any(seq.startswith(rest) for seq in KEY_SEQUENCES):
                return keys, rest  # the rest of an escape sequence has not arrived yet
            i += 1
    return keys, b''


@dataclass(frozen=True)
class FreeDrive:
    """Free-mode command steps and limits: each Up/Down changes V by ``speed_step_m_s`` [m/s], each
    Left/Right the yaw rate by ``yaw_step_rad_s`` [rad/s] (+ = left, REP 103), clamped to the limits."""

    speed_step_m_s: float = 0.05
    yaw_step_rad_s: float = 0.05
    max_speed_m_s: float = 0.5
    max_yaw_rate_rad_s: float = 1.0

    def apply(self, command: tuple[float, float], key: str) -> tuple[float, float]:
        """The command (V [m/s], yaw rate [rad/s]) after ``key``."""
        speed, yaw = command
        if key == 'up':
            speed += self.speed_step_m_s
        elif key == 'down':
            speed -= self.speed_step_m_s
        elif key == 'left':
            yaw += self.yaw_step_rad_s
        elif key == 'right':
            yaw -= self.yaw_step_rad_s
        elif key == 'stop':
            return 0.0, 0.0
        speed = max(-self.max_speed_m_s, min(self.max_speed_m_s, round(speed, 9)))
        yaw = max(-self.max_yaw_rate_rad_s, min(self.max_yaw_rate_rad_s, round(yaw, 9)))
        return speed, yaw


# --- case mode ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class CaseProfile:
    """A sequence of command :class:`Segment`; after the last one the command is (0, 0), the case done."""

    steps: tuple[Segment, ...]

    def __post_init__(self) -> None:
        if not self.steps:
            raise InputError('a case profile needs at least one step')
        for k, step in enumerate(self.steps, 1):
            values = (step.duration_s, step.speed_m_s, step.yaw_rate_rad_s)
            if not all(math.isfinite(v) for v in values):
                raise InputError(f'case step {k}: values must be finite numbers')
            if step.duration_s <= 0:
                raise InputError(f'case step {k}: duration must be > 0 s, got {step.duration_s:g}')

    @property
    def duration_s(self) -> float:
        return sum(step.duration_s for step in self.steps)

    def command_at(self, elapsed_s: float) -> tuple[float, float] | None:
        """(V, yaw rate) at ``elapsed_s`` [s] since the start; None once the profile is over."""
        end = 0.0
        for step in self.steps:
            end += step.duration_s
            if elapsed_s < end:
                return step.speed_m_s, step.yaw_rate_rad_s
        return None


CASE_COLUMNS = ('duration_s', 'speed_m_s', 'yaw_rate_rad_s')


def load_case_csv(path: str | os.PathLike[str]) -> CaseProfile:
    """Read a case profile: CSV with header ``duration_s,speed_m_s,yaw_rate_rad_s`` (SI units).

    Raises InputError naming the file and line for anything malformed.
    """
    source = Path(path)
    try:
        with source.open(newline='', encoding='utf-8') as handle:
            rows = list(csv.DictReader(line for line in handle if not line.lstrip().startswith('#')))
    except OSError as err:
        raise InputError(f'cannot read case file {source}: {err.strerror or err}') from err
    if not rows or any(col not in rows[0] for col in CASE_COLUMNS):
        raise InputError(f'case file {source}: need a header with columns {", ".join(CASE_COLUMNS)}')
    steps = []
    for line, row in enumerate(rows, 2):
        try:
            values = {col: float(row[col]) for col in CASE_COLUMNS}
        except (TypeError, ValueError):
            raise InputError(f'case file {source}, line {line}: not a number in {dict(row)}') from None
        try:
            steps.append(Segment(**values))
        except InputError as err:
            raise InputError(f'case file {source}, line {line}: {err}') from None
    try:
        return CaseProfile(tuple(steps))
    except InputError as err:
        raise InputError(f'case file {source}: {err}') from None


# --- what is shown ------------------------------------------------------------------------------
@dataclass
class MonitorView:
    """Everything the view shows, SI units; NaN where nothing has arrived."""

    mode: str = 'free'
    command: tuple[float, float] = (0.0, 0.0)
    case_elapsed_s: float = math.nan
    case_total_s: float = math.nan
    ready: bool = False
    summary: dict[str, float] = field(default_factory=dict)
    motor_speed_rad_s: tuple[float, float] = (math.nan, math.nan)
    motor_current_A: tuple[float, float] = (math.nan, math.nan)
    soc: float = math.nan
    voltage_V: float = math.nan
    remaining_wh: float = math.nan
    time_to_empty_s: float = math.nan
    time_to_empty_p10_s: float = math.nan  # energy/time_to_empty_p10_s [s] (power_estimator)
    time_to_empty_p90_s: float = math.nan  # energy/time_to_empty_p90_s [s]
    path_required_wh: float = math.nan  # energy/path_required_wh [Wh]
    path_margin_wh: float = math.nan  # energy/path_margin_wh [Wh]
    status: str = ''
    stale: frozenset[str] = frozenset()
    """Sources (:data:`SOURCES`) not heard from for :data:`STALE_AFTER_S`; their values are greyed."""

    def get(self, name: str) -> float:
        return float(self.summary.get(name, math.nan))


def _num(value: float, fmt: str) -> str:
    return '--' if not math.isfinite(value) else format(value, fmt)


def format_duration(seconds: float) -> str:
    """h:mm:ss, '--' when unknown, 'idle' when infinite (nothing drawn)."""
    if math.isnan(seconds):
        return '--'
    if math.isinf(seconds):
        return 'idle'
    seconds = max(0, round(seconds))
    return f'{seconds // 3600}:{seconds % 3600 // 60:02d}:{seconds % 60:02d}'


def _stale_label(label: str, stale: bool) -> Text:
    return Text(f'{label} (stale)', style='dim') if stale else Text(label)


def _motor_table(view: MonitorView) -> Table:
    table = Table(title='Motors and power', expand=True)
    table.add_column('')
    table.add_column('left', justify='right')
    table.add_column('right', justify='right')
    rows = [
        ('speed [rpm]', [v * RPM_PER_RAD_S for v in view.motor_speed_rad_s], '.0f', 'joint_states'),
        ('current [A]', list(view.motor_current_A), '.2f', 'joint_states'),
        (
            'predicted power [W]',
            [view.get('predicted_left_W'), view.get('predicted_right_W')],
            '.1f',
            'summary',
        ),
        (
            'corrected (online) [W]',
            [view.get('corrected_left_W'), view.get('corrected_right_W')],
            '.1f',
            'summary',
        ),
        ('measured power [W]', [view.get('measured_left_W'), view.get('measured_right_W')], '.1f', 'summary'),
        ('error meas-pred [W]', [view.get('error_left_W'), view.get('error_right_W')], '+.1f', 'summary'),
    ]
    standing = view.get('cmd_vel_stale') == 1.0  # no command in force: the robot is held at zero
    for label, (left, right), fmt, source in rows:
        stale = source in view.stale
        style = 'dim' if stale else ''
        if standing and source == 'summary' and not stale and label.startswith(('predicted', 'corrected')):
            label, style = f'{label.split(" [")[0]} (standing) [W]', 'dim'  # not a command's figure
        table.add_row(
            _stale_label(label, stale),
            Text(_num(left, fmt), style=style),
            Text(_num(right, fmt), style=style),
        )
    return table


def _tte_band(view: MonitorView) -> str:
    """' (p10 h:mm:ss - p90 h:mm:ss)' of the time to empty, '' until both have arrived."""
    if math.isnan(view.time_to_empty_p10_s) or math.isnan(view.time_to_empty_p90_s):
        return ''
    low, high = format_duration(view.time_to_empty_p10_s), format_duration(view.time_to_empty_p90_s)
    return f' (p10 {low} - p90 {high})'


class Gauge:
    """The battery gauge: ``fraction`` [-] of the width it is given filled (76 of 80 columns in an
    80x24 terminal's panel), not a fixed width."""

    def __init__(self, fraction: float, colour: str) -> None:
        self.fraction = fraction
        self.colour = colour

    def __rich_console__(self, console: Console, options: ConsoleOptions) -> RenderResult:
        width = max(1, options.max_width)
        filled = round(width * self.fraction)
        yield Text.assemble(('█' * filled, self.colour), ('░' * (width - filled), 'dim'))


def _battery_panel(view: MonitorView) -> Panel:
    soc = view.soc
    colour = 'red' if soc < 0.2 else 'yellow' if soc < 0.4 else 'green'
    fraction = 0.0 if math.isnan(soc) else min(max(soc, 0.0), 1.0)
    gauge = Gauge(fraction, colour)
    source = view.get('energy_source')
    source_name = SOURCE_NAMES[int(source)] if math.isfinite(source) and 0 <= source < 3 else '--'
    lines = Text.assemble(
        f'charge {_num(100.0 * soc, ".1f")} %   {_num(view.remaining_wh, ".1f")} Wh   ',
        f'{_num(view.voltage_V, ".1f")} V\n',
        f'time to empty {format_duration(view.time_to_empty_s)}{_tte_band(view)}\n',
        f'battery power: predicted {_num(view.get("predicted_battery_W"), ".1f")} W, ',
        f'corrected {_num(view.get("corrected_battery_W"), ".1f")} W, ',
        f'measured {_num(view.get("measured_battery_W"), ".1f")} W (energy from {source_name})\n',
        f'command V {_num(view.get("speed_cmd_m_s"), ".2f")} m/s, yaw rate '
        f'{_num(view.get("yaw_rate_cmd_rad_s"), ".2f")} rad/s -> predicted motion '
        f'V {_num(view.get("predicted_motion_speed_m_s"), ".2f")} m/s, yaw rate '
        f'{_num(view.get("predicted_motion_yaw_rate_rad_s"), ".2f")} rad/s (set points: the wheels slip)',
    )
    if math.isfinite(view.path_required_wh):
        short = math.isfinite(view.path_margin_wh) and view.path_margin_wh < 0
        lines.append(
            f'\nplanned path needs {_num(view.path_required_wh, ".2f")} Wh, '
            f'margin after return {_num(view.path_margin_wh, ".2f")} Wh',
            style='bold red' if short else None,
        )
    if 'battery' in view.stale:
        gauge.colour = 'dim'
        lines.stylize('dim')
        return Panel(Group(gauge, lines), title='Battery (stale)', style='dim')
    return Panel(Group(gauge, lines), title='Battery')


def _traction_text(view: MonitorView) -> Text:
    margin = view.get('traction_margin')
    if 'summary' in view.stale:
        return Text(f'traction margin {_num(margin, ".2f")} (stale)', style='dim')
    if view.get('traction_warning') == 1.0:
        return Text(
            f'TRACTION WARNING: margin {_num(margin, ".2f")} - the robot may get stuck', style='bold red'
        )
    return Text(f'traction margin {_num(margin, ".2f")}', style='green' if math.isfinite(margin) else 'dim')


def render(view: MonitorView) -> Group:
    """The whole screen for ``view`` (a rich renderable; print it with any rich Console)."""
    ready = Text('Ready', style='bold green') if view.ready else Text('Not Ready', style='bold red')
    speed, yaw = view.command
    case = ''
    if view.mode == 'case':
        case = f'  case {_num(view.case_elapsed_s, ".1f")} / {_num(view.case_total_s, ".1f")} s'
    command = f'command V {speed:+.2f} m/s, yaw rate {yaw:+.2f} rad/s'
    header = Text.assemble(  # one line in 80 columns, 'Not Ready' and case mode too (80 at most)
        ready,
        f'  {view.mode}  ',
        (f'{command} (stale)', 'dim') if 'command' in view.stale else command,
        case,
    )
    share = view.get('terrain_share')
    split = Text(
        f'terrain {_num(view.get("terrain_W"), ".1f")} W, internal {_num(view.get("internal_W"), ".1f")} W '
        f'(terrain share {_num(100.0 * share, ".0f")} %)'
    )
    if 'summary' in view.stale:
        split.append(' (stale)')
        split.stylize('dim')
    parts: list[RenderableType] = [
        header,
        _motor_table(view),
        split,
        _traction_text(view),
        _battery_panel(view),
    ]
    if view.stale >= {'joint_states', 'summary', 'battery'}:
        parts.append(
            Text('no data from the robot: values shown are the last received (stale)', style='bold yellow')
        )
    if view.status:
        parts.append(Text(view.status, style='yellow'))
    if view.mode == 'free':
        parts.append(Text('keys: Up/Down speed, Left/Right turn, Space stop, q quit', style='dim'))
    return Group(*parts)


# --- CSV of what was shown ----------------------------------------------------------------------
CSV_COLUMNS = (
    'time_s', 'mode', 'speed_cmd_m_s', 'yaw_rate_cmd_rad_s', 'ready',
    'motor_speed_left_rad_s', 'motor_speed_right_rad_s', 'current_left_A', 'current_right_A',
    'predicted_left_W', 'predicted_right_W', 'measured_left_W', 'measured_right_W',
    'predicted_battery_W', 'measured_battery_W', 'terrain_W', 'internal_W',
    'traction_margin', 'traction_warning', 'soc', 'remaining_wh', 'time_to_empty_s', 'energy_source',
    'time_to_empty_p10_s', 'time_to_empty_p90_s',
    'corrected_left_W', 'corrected_right_W', 'corrected_battery_W',
)  # fmt: skip


def csv_row(view: MonitorView, time_s: float) -> list[str]:
    """One CSV row (columns :data:`CSV_COLUMNS`) of what ``view`` shows at ``time_s`` [s]."""
    values: list[object] = [
        time_s, view.mode, view.command[0], view.command[1], int(view.ready),
        *view.motor_speed_rad_s, *view.motor_current_A,
        *(view.get(k) for k in ('predicted_left_W', 'predicted_right_W',
                                'measured_left_W', 'measured_right_W',
                                'predicted_battery_W', 'measured_battery_W', 'terrain_W', 'internal_W',
                                'traction_margin', 'traction_warning')),
        view.soc, view.remaining_wh, view.time_to_empty_s, view.get('energy_source'),
        view.time_to_empty_p10_s, view.time_to_empty_p90_s,
        *(view.get(k) for k in ('corrected_left_W', 'corrected_right_W', 'corrected_battery_W')),
    ]  # fmt: skip
    return [f'{v:.6g}' if isinstance(v, float) else str(v) for v in values]


class CsvLog:
    """Appends what the monitor shows to a CSV file (header first), flushed row by row."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._handle = self.path.open('w', newline='', encoding='utf-8')
        self._writer = csv.writer(self._handle)
        self._writer.writerow(CSV_COLUMNS)
        self.rows = 0

    def write(self, rows: Iterable[Sequence[str]]) -> None:
        for row in rows:
            self._writer.writerow(row)
            self.rows += 1
        self._handle.flush()

    def close(self) -> None:
        if not self._handle.closed:
            self._handle.close()
