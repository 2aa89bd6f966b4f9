"""Battery pack: open-circuit voltage vs state of charge, internal resistance, coulomb counting.

Equivalent circuit (one lumped cell string, SI units)::

    V_terminal = V_oc(SOC) - R i,      P = V_terminal i = V_oc i - R i^2
    i(P) = (V_oc - sqrt(V_oc^2 - 4 R P)) / (2 R)          (the smaller root: the normal operating branch)
    dSOC/dt = -i / Q                                       (coulomb counting; Q = capacity [C])

At constant power the discharge is the ODE above; its time to empty is
t = integral_{SOC_empty}^{SOC} Q / i(P, SOC') dSOC', in closed form: Q / i = Q (V_oc + sqrt(V_oc^2 - 4 R P))
/ (2 P) and V_oc is linear in SOC between table points, so each piece integrates exactly
(integral sqrt(u^2 - c) du = u sqrt(u^2 - c) / 2 - c ln(u + sqrt(u^2 - c)) / 2). It replaced scipy
``quad`` (the estimator evaluates it at 5 Hz, three times a tick: ~0.5 ms per call with ``quad``;
the test compares both). :meth:`Battery.step` integrates the same ODE (RK4 sub-steps), so a battery
drained at constant power empties at the computed time.
Remaining energy is the open-circuit energy Q integral V_oc dSOC (what a lossless load could draw);
:meth:`Battery.remaining_wh_at` subtracts the internal-resistance loss at a given load.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.powertrain.config import merged

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject

SECONDS_PER_HOUR = 3600.0
_MAX_SUBSTEP_SOC = 0.002  # RK4 sub-step size in SOC, small enough for the piecewise-linear OCV curve


@dataclass(frozen=True)
class BatteryConfig:
    """Pack parameters (SI units; see config/batteries/*.yaml).

    Attributes
    ----------
    name : preset name
    cells_in_series_per_pack, packs_in_series, packs_in_parallel : topology [-]
    capacity_Ah : capacity of one pack [A h]
    cell_resistance_ohm : internal resistance of one cell [ohm]
    soc_points, cell_ocv_V : open-circuit voltage of one cell [V] at the state-of-charge points [-]
    soc_empty : state of charge counted as empty [-]
    mass_kg : battery mass [kg]
    source : provenance
    chemistry : cell chemistry as the battery file names it ('LiPo', 'Li-ion' ...; '' = unknown)
    """

    name: str
    cells_in_series_per_pack: int
    packs_in_series: int
    packs_in_parallel: int
    capacity_Ah: float
    cell_resistance_ohm: float
    soc_points: tuple[float, ...]
    cell_ocv_V: tuple[float, ...]
    soc_empty: float = 0.0
    mass_kg: float = 0.0
    source: str = ''
    chemistry: str = ''

    @property
    def cells_in_series(self) -> int:
        return self.cells_in_series_per_pack * self.packs_in_series

    @property
    def capacity_C(self) -> float:
        """Charge capacity of the whole battery [C]."""
        return self.capacity_Ah * self.packs_in_parallel * SECONDS_PER_HOUR

    @property
    def resistance_ohm(self) -> float:
        """Internal resistance of the whole battery [ohm]."""
        return self.cell_resistance_ohm * self.cells_in_series / self.packs_in_parallel

    @functools.cached_property
    def max_power_W(self) -> float:
        """Largest terminal power [W] the pack can deliver at ANY state of charge; computed once.

        Maximum power transfer from an OCV source behind resistance R is OCV^2 / (4 R); the lowest
        OCV of the curve gives the bound valid at every state of charge, so a power within it never
        makes :meth:`Battery.current_for_power`, :meth:`Battery.step` or
        :meth:`Battery.time_to_empty_s` fail.
        """
        v_min = float(np.min(self.ocv(self.soc_points)))
        return v_min * v_min / (4.0 * self.resistance_ohm)

    def pieces(self, soc_low: float, soc_high: float) -> np.ndarray:
        """The states of charge [-] from ``soc_low`` to ``soc_high`` where the piecewise-linear OCV
        curve bends, both ends included, strictly increasing (``[soc_high]`` when the range is empty).

        The table's points are strictly increasing (checked when the config is read), so the bends
        are its points strictly inside the range: picked in plain Python, 1.2 us where np.unique took
        14 us (measured), three times per estimator tick (issue 18)."""
        if soc_high <= soc_low:
            return np.array([soc_high])
        return np.array([soc_low, *(s for s in self.soc_points if soc_low < s < soc_high), soc_high])

    def ocv(self, soc: float | Sequence[float] | NDArray[np.float64]) -> NDArray[np.float64] | np.float64:
        """Open-circuit voltage of the battery [V] at state of charge ``soc`` [-] (linear in the table).

        A scalar ``soc`` gives a scalar, an array an array of its shape.
        """
        return self.cells_in_series * np.interp(soc, self.soc_points, self.cell_ocv_V)

    def as_dict(self) -> JsonObject:
        data = asdict(self)
        data['soc_points'] = list(self.soc_points)
        data['cell_ocv_V'] = list(self.cell_ocv_V)
        return data


@dataclass
class BatteryState:
    """Present state of the battery.

    Attributes
    ----------
    soc : state of charge [-]
    charge_C : remaining charge above empty [C]
    energy_Wh : remaining open-circuit energy above empty [W h]
    ocv_V : open-circuit voltage [V]
    voltage_V : terminal voltage at the last load [V]
    current_A : last current [A] (positive = discharge)
    power_W : last power [W] (positive = discharge)
    elapsed_s : time integrated so far [s]
    drawn_J : net energy drawn at the terminals so far [J]
    """

    soc: float
    charge_C: float = 0.0
    energy_Wh: float = 0.0
    ocv_V: float = 0.0
    voltage_V: float = 0.0
    current_A: float = 0.0
    power_W: float = 0.0
    elapsed_s: float = 0.0
    drawn_J: float = 0.0


@dataclass
class Battery:
    """A battery with coulomb counting; ``step`` it with the bus power to track its state."""

    config: BatteryConfig
    state: BatteryState = field(default_factory=lambda: BatteryState(soc=1.0))

    def __post_init__(self) -> None:
        self._refresh(current=self.state.current_A, power=self.state.power_W)

    @classmethod
    def from_config(cls, config: Mapping[str, object] | str | None, soc: float = 1.0) -> Battery:
        """Build from a mapping (``preset`` expanded) or a preset name; full unless ``soc`` [-] given."""
        if config is None or isinstance(config, str):
            config = {'preset': config or 'test_robot'}
        battery = cls(_parse_config(merged('batteries', config)), BatteryState(soc=_soc(soc)))
        return battery

    @classmethod
    def default_test_robot(cls, soc: float = 1.0) -> Battery:
        """Two 6-cell 5000 mAh LiPo packs in series (ch. 7.1.2; config/batteries/test_robot.yaml)."""
        return cls.from_config('test_robot', soc)

    # -- state ------------------------------------------------------------------------------------
    @property
    def soc(self) -> float:
        return self.state.soc

    @property
    def remaining_wh(self) -> float:
        """Open-circuit energy left above empty [W h]."""
        return self.state.energy_Wh

    @property
    def is_empty(self) -> bool:
        return self.state.soc <= self.config.soc_empty + 1e-12

    def max_power_W(self) -> float:
        """Largest terminal power [W] the battery can deliver at ANY state of charge
        (:attr:`BatteryConfig.max_power_W`)."""
        return self.config.max_power_W

    def with_state(self, state: BatteryState) -> Battery:
        """This battery's configuration in ``state`` (a restart restores the tallies)."""
        return replace(self, state=state)

    def current_for_power(self, power_W: float, soc: float | None = None) -> float:
        """Battery current [A] delivering terminal power ``power_W`` [W] at ``soc`` (default: now)."""
        v = float(self.config.ocv(self.state.soc if soc is None else soc))
        r = self.config.resistance_ohm
        disc = v * v - 4.0 * r * power_W
        if disc < 0:
            raise InputError(
                f'battery cannot deliver {power_W:.1f} W (max {v * v / (4 * r):.1f} W at this SOC)'
            )
        return 2.0 * power_W / (v + math.sqrt(disc))  # = (v - sqrt(disc)) / 2R, without cancellation

    def step(self, power_W: float, dt_s: float) -> None:
        """Draw ``power_W`` [W] (negative = charge, e.g. regeneration) for ``dt_s`` [s].

        Stops at empty (SOC_empty) and at full (SOC 1); coulomb counting by RK4 on dSOC/dt = -i/Q.
        """
        if not (math.isfinite(power_W) and math.isfinite(dt_s)) or dt_s < 0:
            raise InputError(f'battery step needs finite power and dt >= 0, got {power_W}, {dt_s}')
        soc = self.state.soc
        q = self.config.capacity_C
        rate = abs(self.current_for_power(power_W, soc)) / q
        n_sub = max(1, math.ceil(rate * dt_s / _MAX_SUBSTEP_SOC))
        h = dt_s / n_sub
        used = 0.0
        for _ in range(n_sub):
            if (power_W > 0 and soc <= self.config.soc_empty) or (power_W < 0 and soc >= 1.0):
                break
            soc = self._rk4(soc, power_W, h)
            used += h
        soc = min(max(soc, self.config.soc_empty), 1.0)
        self.state.soc = soc
        self.state.elapsed_s += dt_s
        self.state.drawn_J += power_W * used
        self._refresh(current=self.current_for_power(power_W, soc) if used > 0 else 0.0, power=power_W)

    def run_profile(self, power_W: ArrayLike, dt_s: ArrayLike) -> None:
        """Step through a piecewise-constant power profile: ``power_W[k]`` [W] held for ``dt_s[k]`` [s]
        (e.g. a mission's battery power per segment), in order."""
        for power, dt in zip(np.ravel(power_W), np.ravel(dt_s), strict=True):
            self.step(float(power), float(dt))

    def _dsoc(self, soc: float, power_W: float) -> float:
        soc = min(max(soc, 0.0), 1.0)
        return -self.current_for_power(power_W, soc) / self.config.capacity_C

    def _rk4(self, soc: float, power_W: float, h: float) -> float:
        k1 = self._dsoc(soc, power_W)
        k2 = self._dsoc(soc + 0.5 * h * k1, power_W)
        k3 = self._dsoc(soc + 0.5 * h * k2, power_W)
        k4 = self._dsoc(soc + h * k3, power_W)
        return soc + h * (k1 + 2 * k2 + 2 * k3 + k4) / 6.0

    def _refresh(self, current: float, power: float) -> None:
        cfg = self.config
        s = self.state
        s.charge_C = max(s.soc - cfg.soc_empty, 0.0) * cfg.capacity_C
        s.energy_Wh = self._ocv_energy_J(cfg.soc_empty, s.soc) / SECONDS_PER_HOUR
        s.ocv_V = float(cfg.ocv(s.soc))
        s.current_A = float(current)
        s.power_W = float(power)
        s.voltage_V = s.ocv_V - cfg.resistance_ohm * s.current_A

    def _ocv_energy_J(self, soc_low: float, soc_high: float) -> float:
        if soc_high <= soc_low:
            return 0.0
        grid = self.config.pieces(soc_low, soc_high)
        return float(
            np.trapezoid(self.config.ocv(grid), grid) * self.config.capacity_C
        )  # exact: OCV is piecewise linear

    # -- predictions ------------------------------------------------------------------------------
    def time_to_empty_s(self, power_W: float) -> float:
        """Time [s] until empty at constant terminal power ``power_W`` [W]; inf if not discharging."""
        if not math.isfinite(power_W):
            raise InputError(f'power must be finite, not {power_W}')
        if power_W <= 0 or self.is_empty:
            return math.inf if power_W <= 0 else 0.0
        cfg = self.config
        low, high = cfg.soc_empty, self.state.soc
        soc = cfg.pieces(low, high)
        v = np.asarray(cfg.ocv(soc), dtype=float)
        c = 4.0 * cfg.resistance_ohm * power_W
        if float(np.min(v)) ** 2 < c:
            self.current_for_power(power_W, float(soc[np.argmin(v)]))  # raises: cannot deliver
        root = np.sqrt(v * v - c)
        antiderivative = 0.5 * (v * root - c * np.log(v + root))  # of sqrt(u^2 - c) du
        dv, ds = np.diff(v), np.diff(soc)
        flat = np.abs(dv) <= 1e-12 * v[1:]  # a constant piece: sqrt(v^2 - c) ds
        slope = np.where(flat, 1.0, dv / ds)  # ds > 0: pieces() is strictly increasing
        sqrt_part = np.where(flat, root[1:] * ds, np.diff(antiderivative) / slope)
        v_part = 0.5 * (v[1:] + v[:-1]) * ds
        return float(cfg.capacity_C * np.sum(v_part + sqrt_part) / (2.0 * power_W))

    def distance_to_empty_m(self, power_W: float, speed_m_s: float) -> float:
        """Distance [m] until empty driving at ``speed_m_s`` [m/s] with constant power [W]."""
        t = self.time_to_empty_s(power_W)
        return math.inf if math.isinf(t) else t * abs(speed_m_s)

    def remaining_wh_at(self, power_W: float) -> float:
        """Energy [W h] deliverable to a load of constant ``power_W`` [W] (internal losses removed)."""
        t = self.time_to_empty_s(power_W)
        return self.remaining_wh if math.isinf(t) else power_W * t / SECONDS_PER_HOUR

    # -- persistence ------------------------------------------------------------------------------
    def to_dict(self) -> JsonObject:
        """Plain dict (config and state) that :meth:`from_dict` restores, e.g. as JSON or YAML."""
        return {'config': self.config.as_dict(), 'state': asdict(self.state)}

    @classmethod
    def from_dict(cls, data: JsonObject) -> Battery:
        try:
            config = _parse_config(dict(data['config']))
            state = BatteryState(**{k: float(v) for k, v in dict(data['state']).items()})
        except (KeyError, TypeError, ValueError) as err:
            raise ConfigError(f'battery: cannot restore state ({err})') from err
        state.soc = _soc(state.soc)
        return cls(config, state)


def _soc(value: float) -> float:
    soc = float(value)
    if not (0.0 <= soc <= 1.0):
        raise ConfigError(f'battery: state of charge must be in [0, 1], not {value}')
    return soc


def _parse_config(cfg: JsonObject) -> BatteryConfig:
    try:
        curve = cfg.get('ocv_curve') or {}
        soc_points = tuple(float(v) for v in cfg.get('soc_points', curve.get('soc', ())))
        cell_ocv = tuple(float(v) for v in cfg.get('cell_ocv_V', curve.get('cell_V', ())))
        config = BatteryConfig(
            name=str(cfg.get('name', 'custom')),
            cells_in_series_per_pack=int(cfg['cells_in_series_per_pack']),
            packs_in_series=int(cfg.get('packs_in_series', 1)),
            packs_in_parallel=int(cfg.get('packs_in_parallel', 1)),
            capacity_Ah=float(cfg['capacity_Ah']),
            cell_resistance_ohm=float(cfg['cell_resistance_ohm']),
            soc_points=soc_points,
            cell_ocv_V=cell_ocv,
            soc_empty=float(cfg.get('soc_empty', 0.0)),
            mass_kg=float(cfg.get('mass_kg', 0.0)),
            source=str(cfg.get('source', '')),
            chemistry=str(cfg.get('chemistry', '')),
        )
    except (KeyError, TypeError, ValueError) as err:
        raise ConfigError(f'battery config: missing or bad field {err}') from err
    _check(config)
    return config


def _check(cfg: BatteryConfig) -> None:
    soc = np.asarray(cfg.soc_points)
    v = np.asarray(cfg.cell_ocv_V)
    if min(cfg.cells_in_series_per_pack, cfg.packs_in_series, cfg.packs_in_parallel) < 1:
        raise ConfigError('battery config: cell and pack counts must be >= 1')
    if not (cfg.capacity_Ah > 0 and cfg.cell_resistance_ohm > 0):
        raise ConfigError('battery config: capacity_Ah and cell_resistance_ohm must be > 0')
    if soc.size < 2 or soc.size != v.size or np.any(np.diff(soc) <= 0) or soc[0] > 0 or soc[-1] < 1:
        raise ConfigError('battery config: ocv_curve needs increasing soc from 0 to 1 with one voltage each')
    if np.any(np.diff(v) < 0) or np.any(v <= 0):
        raise ConfigError('battery config: open-circuit voltage must be positive and non-decreasing in soc')
    if not (0.0 <= cfg.soc_empty < 1.0):
        raise ConfigError('battery config: soc_empty must be in [0, 1)')
