"""FESS driven by the wheel speed set points: what the robot really does for a command (issue 25).

The amplifiers hold the side (sprocket / axle) speeds; the terrain decides the body motion. A command
(V_cmd [m/s], yaw rate w_cmd [rad/s]) gives the set points with the robot's drive controller
(:mod:`skidsteer_power.drive`: velocity limits, v_side = V -+ w B / 2, omega = v_side / r, the wheel
speed ceiling). FESS (:mod:`skidsteer_power.models.fess`) is then solved
the other way round: the side speeds are given and the unknowns are the body motion (V, w_z) and the
turning-centre offset s0, under the same three equilibrium equations of eq. 3.19 (sum F_x, sum F_y,
sum M_z). Writing the set points as two more equations (omega_left = sp_left, omega_right =
sp_right) around FESS's three-unknown system and eliminating them leaves a 3 x 3 system in
(s0, V, w_z), solved for the whole batch by the project's batched Newton
(:func:`~skidsteer_power.models.newton.newton_solve`, eqs. 3.20-3.22). The vertical loads (eq. 6.12)
and the contacts are rebuilt from the trial (V, w_z) at every residual call.

Symmetry: a set point pair with a negative mean is solved as the fore-aft mirror image of the
positive one (module doc of fess.py), so reversing is exact; equal set points are straight running
(w_z pinned at 0, s0 by FESS's straight-running limit); opposite set points are a spin (V = 0 by
symmetry, reached by the Newton iteration, not imposed).

Where no steady state exists (Newton finds no equilibrium, also after a continuation from straight
running, or a side would have to slip more than :data:`~skidsteer_power.models.fess.SLIP_LIMIT`)
the answer is the robot dug in: V = 0, w_z = 0, the wheels turning at their set points with the
shear torque of the spinning contacts, ``limited`` and a ``reason``.

The pivot band on soil (tight turns with the inner side near standstill or slightly reversed, issue
36): there an inner element turns past half a revolution while in the contact (eqs. 6.3, 6.5,
:func:`element_turn_rev`), and eq. 6.6's chord from the gripped ground point shrinks and turns across
the slip although the soil is sheared further; its roots there have torques that jump by a factor 3
between set points 2 % apart. Those points (dug in, or a root past :data:`ELEMENT_TURN_LIMIT_REV`)
are re-solved with FESS's pivot law (``FessSolver(path_law=True)``, :func:`~skidsteer_power.models.
fess_problem.pivot_blend`): each element keeps the chord up to half a revolution, then its displacement
blends into its slip path, the plastic-flow law of the rigid contact. Below half a revolution the two
laws are the same numbers, so the answers outside the band are unchanged and the torque is
continuous across its edge (docs/PREDICTION.md, "The pivot band"; test/test_fess_pivot_band.py).
In that re-solve a pivot's inner side may also sit at rest over the ground (its compaction
resistance anywhere in [-R_c, R_c]: :func:`~skidsteer_power.models.fess_problem.rolling_direction`; exempt
from the slip limit while the body turns the way the set points ask). A point the pivot law does not
solve either keeps the chord's answer and flag: ``limited``, dug in (:data:`REASON_TRACTION`) or past
half a revolution (:data:`REASON_PIVOT`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.drive.controller import DriveController, wheels_to_twist
from skidsteer_power.errors import InputError
from skidsteer_power.models.fess import FessSolver, _outputs, residual
from skidsteer_power.models.fess_problem import FORCE_TOL_N, SLIP_LIMIT, steeds_s0
from skidsteer_power.models.newton import NewtonResult, newton_solve
from skidsteer_power.vehicle import TrackGear

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from skidsteer_power.models.fess_problem import Problem
    from skidsteer_power.models.fess_steady import TwistSolution

SETPOINT_MAX_ITERATIONS = 60
CONTINUATION_STEPS = 8  # steps from straight running to a failed point's set points
# Past half a revolution of the body while an element crosses the contact (eqs. 6.3, 6.5), eq. 6.6's
# chord from the gripped ground point shrinks although the soil is sheared further: FESS's torque
# there is erratic (docs/PREDICTION.md, "The pivot band"), so such a root is not a usable answer.
ELEMENT_TURN_LIMIT_REV = 0.5
REASON_OK = ''
REASON_TRACTION = (
    'no steady state found at these set points (a traction limit, or a tight turn with the inner side near '
    'standstill where FESS has none); the values are the dug-in state: V = 0, wheels at their set points'
)
REASON_PIVOT = (
    'tight turn with the inner side near standstill: an element turns past half a revolution while in '
    "the contact, where FESS's shear displacement (eq. 6.6) stops growing; the motion is FESS's root, "
    "the torques are outside the model's validity"
)


def command_setpoints(
    speed_cmd: ArrayLike, yaw_cmd: ArrayLike, *, tread_m: float, drive_radius_m: float, max_axle_rad_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Side axle speed set points [rad/s] (P, 2) (left, right) for commands (V [m/s], w_z [rad/s]).

    A drive controller with this geometry, no velocity limit and the ceiling ``max_axle_rad_s``
    scaled (:meth:`skidsteer_power.drive.DriveController.apply`): if a side would pass it, both are
    scaled by the same factor (the path curvature is kept). Returns (set points, clamped (P,) bool).
    """
    ctrl = DriveController(tread_m, drive_radius_m, max_wheel_rad_s=max_axle_rad_s)
    out = ctrl.apply(speed_cmd, yaw_cmd)
    return out.setpoint, out.clamped


@dataclass
class SetpointSolution:
    """Steady state of a batch of P set point pairs, per side (left, right), SI units.

    speed, yaw_rate : body motion V [m/s], w_z [rad/s] the set points produce
    s0 : turning-centre offset ahead of the CG [m]
    omega : (P, 2) side axle speeds [rad/s] (the set points)
    torque : (P, 2) axle torque the terrain asks for [N m]
    slip : (P, 2) [-] eq. 2.13
    sinkage : (P,) largest sinkage [m]
    traction_margin : (P,) 1 - required / available thrust [-]
    limited : (P,) no usable steady state; reason says why: ``dug_in`` (no root: the prediction is the
        dug-in state) or an element turning past :data:`ELEMENT_TURN_LIMIT_REV` (FESS's root is kept)
    dug_in : (P,) no root was found; the values are the dug-in state (V = 0, wheels at the set points)
    element_turn : (P,) the body's turn while an element crosses the slower side's contact [rev]
        (:func:`element_turn_rev`)
    contact_length : (P,) the longer contact length behind the entry of the two sides [m]
    iterations : (P,) Newton steps
    shear_path : (P,) solved with the slip path in the shear law (rigid ground: always; soil: the
        pivot band, by the pivot law of :func:`~skidsteer_power.models.fess_problem.pivot_blend`), where
        the element-turn test does not apply
    """

    speed: np.ndarray
    yaw_rate: np.ndarray
    s0: np.ndarray
    omega: np.ndarray
    torque: np.ndarray
    slip: np.ndarray
    sinkage: np.ndarray
    traction_margin: np.ndarray
    limited: np.ndarray
    reason: list[str]
    iterations: np.ndarray
    dug_in: np.ndarray
    element_turn: np.ndarray
    contact_length: np.ndarray
    shear_path: np.ndarray

    def take(self, rows: np.ndarray) -> SetpointSolution:
        """The solution of the points ``rows`` (indices) only."""
        arrays = {f.name: getattr(self, f.name)[rows] for f in fields(self) if f.name != 'reason'}
        return SetpointSolution(reason=[self.reason[k] for k in rows], **arrays)

    def replace_rows(self, rows: np.ndarray, other: SetpointSolution) -> None:
        """Overwrite the points ``rows`` (indices) with ``other``'s, in order (len(rows) points)."""
        for f in fields(self):
            if f.name != 'reason':
                getattr(self, f.name)[rows] = getattr(other, f.name)
        for k, reason in zip(rows, other.reason, strict=True):
            self.reason[k] = reason

    @property
    def turn_radius(self) -> np.ndarray:
        """Signed R = V / w_z [m]: +-inf straight, 0 spinning in place, NaN at rest."""
        with np.errstate(divide='ignore', invalid='ignore'):
            return np.where(
                self.yaw_rate == 0, np.where(self.speed == 0, np.nan, np.inf), self.speed / self.yaw_rate
            )

    @property
    def state(self) -> np.ndarray:
        """(P, 3) (s0, V, w_z) to warm-start a later solve."""
        return np.column_stack([self.s0, self.speed, self.yaw_rate])


def no_slip_motion(setpoints: np.ndarray, drive_radius_m: float, tread_m: float) -> np.ndarray:
    """(P, 2) (V, w_z) of the set points with no slip: the drive layer's inverse kinematics
    (:func:`~skidsteer_power.drive.controller.wheels_to_twist`) with the vehicle's geometry."""
    return np.column_stack(wheels_to_twist(setpoints, drive_radius_m, drive_radius_m, tread_m))


class SetpointSolver:
    """FESS at given side speeds for one vehicle and terrain (wraps a :class:`FessSolver`)."""

    def __init__(self, fess: FessSolver) -> None:
        self.fess = fess
        veh = fess.vehicle
        self.radius = float(veh.drive_radius_m)
        self.tread = float(veh.tread_m)
        self._path: SetpointSolver | None = None

    def solve(
        self, setpoints: ArrayLike, *, x0: np.ndarray | None = None, tol: float = FORCE_TOL_N
    ) -> SetpointSolution:
        """Solve P set point pairs (P, 2) [rad/s] (left, right axle speeds) at once.

        ``x0`` (P, 3) = (s0, V, w_z) warm-starts the Newton iteration (e.g. a previous
        :attr:`SetpointSolution.state`); non-finite rows use the no-slip first guess.
        """
        sp = np.atleast_2d(np.asarray(setpoints, dtype=float))
        if sp.ndim != 2 or sp.shape[1] != 2 or not np.all(np.isfinite(sp)):
            raise InputError('set points must be finite (left, right) axle speeds in rad/s')
        flip = np.where(sp.sum(axis=1) < 0, -1.0, 1.0)  # reverse: the fore-aft mirror image
        spf = sp * flip[:, None]
        rest = np.all(spf == 0, axis=1)
        straight = spf[:, 0] == spf[:, 1]
        guess = self._first_guess(spf)
        if x0 is not None:
            warm = np.asarray(x0, dtype=float) * flip[:, None]
            guess = np.where(np.isfinite(warm), warm, guess)
        guess[straight, 2] = 0.0
        result = self._newton(spf, straight, guess, rest, tol)
        self._continue_failed(spf, straight, result, tol)
        out = self._outputs(sp, spf, flip, straight, rest, result)
        if not self.fess.path_law and np.any(out.limited):
            self._pivot_fallback(sp, out, tol)
        return out

    def _pivot_fallback(self, sp: np.ndarray, out: SetpointSolution, tol: float) -> None:
        """Re-solve the points eq. 6.6's chord leaves without a usable steady state (dug in, or an
        element past half a revolution) with FESS's pivot law (:func:`~skidsteer_power.models.fess.
        pivot_blend`: the chord up to half a revolution of an element, its slip path past it), which
        stays meaningful however far an element turns (issue 36: a pivot turn's inner side slightly
        reversed). A root it finds replaces the point's answer, no longer limited; the others keep
        theirs. Updates ``out``."""
        idx = np.flatnonzero(out.limited)
        path = self.path_solver().solve(sp[idx], tol=tol)
        ok = ~path.limited
        if not np.any(ok):
            return
        out.replace_rows(idx[ok], path.take(np.flatnonzero(ok)))

    def path_solver(self) -> SetpointSolver:
        """The same solve with the pivot law (``path_law=True``; built once). It equals eq. 6.6's
        chord wherever no element turns past half a revolution (:func:`~skidsteer_power.models.
        fess_problem.pivot_blend`), so where :meth:`solve` falls back to it, solving with it at once
        gives the same steady state."""
        if self._path is None:
            f = self.fess
            self._path = SetpointSolver(FessSolver(f.vehicle, f.terrain, f.n, path_law=True))
        return self._path

    def _first_guess(self, spf: np.ndarray) -> np.ndarray:
        """(s0, V, w_z): the no-slip motion and the s0 guess of FESS (Steeds' eq. 3.7 form)."""
        motion = no_slip_motion(spf, self.radius, self.tread)
        if self.fess.terrain.is_rigid:  # a driving slip orients the friction (rigid_contact)
            from skidsteer_power.models.rigid_contact import straight_slip_guess

            motion[:, 0] *= 1.0 - straight_slip_guess(self.fess.vehicle, self.fess.terrain)
        s0 = steeds_s0(motion[:, 0], np.abs(motion[:, 1]), self._length_scale())
        return np.column_stack([s0, motion])

    def _length_scale(self) -> float:
        gear = self.fess.vehicle.gear
        if isinstance(gear, TrackGear):
            return float(gear.track_length_m)
        return float(gear.wheelbase_m) + 2 * float(gear.wheel_radius_m)

    def _residual(
        self, spf: np.ndarray, straight: np.ndarray
    ) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
        def fn(x: np.ndarray, idx: np.ndarray) -> np.ndarray:
            s0, v, w = x[:, 0], x[:, 1], np.where(straight[idx], 0.0, x[:, 2])
            prob = self.fess.problem(v, w)
            state = np.column_stack([s0, spf[idx]])[:, None, :]
            f = residual(prob, state)[:, 0]
            f[:, 2] = np.where(straight[idx], x[:, 2], f[:, 2])  # straight: w_z = 0 (symmetry)
            return f

        return fn

    def _newton(
        self, spf: np.ndarray, straight: np.ndarray, guess: np.ndarray, rest: np.ndarray, tol: float
    ) -> NewtonResult:
        n = len(spf)
        x = guess.copy()
        x[rest] = 0.0
        out = NewtonResult(x, np.zeros((n, 3)), rest.copy(), np.zeros(n, dtype=int))
        todo = np.flatnonzero(~rest)
        if todo.size == 0:
            return out
        length = self._length_scale()
        v_ref = np.maximum(np.max(np.abs(spf), axis=1) * self.radius, 1e-3)
        w_ref = 2 * v_ref / self.tread

        def limit(xa: np.ndarray, dx: np.ndarray, idx: np.ndarray) -> np.ndarray:
            caps = np.column_stack(
                [np.full(len(idx), 0.2 * length), 0.5 * v_ref[todo][idx], 0.5 * w_ref[todo][idx]]
            )
            fraction: np.ndarray = 1.0 / np.maximum(np.max(np.abs(dx) / caps, axis=1), 1.0)
            return fraction

        fn = self._residual(spf[todo], straight[todo])
        steps = np.array([1e-7 * length, 1e-7, 1e-7])
        res = newton_solve(
            fn, guess[todo], steps=steps, tol=tol, max_iter=SETPOINT_MAX_ITERATIONS, limit_step=limit
        )
        out.x[todo], out.residual[todo] = res.x, res.residual
        out.converged[todo], out.iterations[todo] = res.converged, res.iterations
        return out

    def _continue_failed(
        self, spf: np.ndarray, straight: np.ndarray, result: NewtonResult, tol: float
    ) -> None:
        """Re-solve the points Newton missed by continuation: the set points' difference grows from 0
        (straight running at their mean) to its full value in CONTINUATION_STEPS steps, each solve
        warm-started from the last (the steady state moves smoothly with the set points). Updates
        ``result`` where the last step converges."""
        failed = np.flatnonzero(~result.converged)
        if failed.size == 0:
            return
        target = spf[failed]
        mean = target.mean(axis=1, keepdims=True)
        x = self._first_guess(np.repeat(mean, 2, axis=1))
        x[:, 2] = 0.0
        ok = np.ones(failed.size, dtype=bool)
        for lam in np.linspace(0.0, 1.0, CONTINUATION_STEPS + 1):
            sp = mean + lam * (target - mean)
            flat = sp[:, 0] == sp[:, 1]
            x[flat, 2] = 0.0
            step = self._newton(sp, flat, x, np.all(sp == 0, axis=1), tol)
            x = np.where(step.converged[:, None], step.x, x)
            ok &= step.converged
        result.x[failed[ok]] = x[ok]
        result.converged[failed[ok]] = True

    def _outputs(
        self,
        sp: np.ndarray,
        spf: np.ndarray,
        flip: np.ndarray,
        straight: np.ndarray,
        rest: np.ndarray,
        result: NewtonResult,
    ) -> SetpointSolution:
        x = result.x.copy()
        x[straight, 2] = 0.0
        sol, prob = self._fess_outputs(x, spf, result.converged, rest)
        dug_in = ~sol.converged
        contact_length = np.broadcast_to(np.max(prob.contact.xi, axis=(-3, -2, -1)), dug_in.shape)
        inner_rim = np.min(np.abs(spf), axis=1) * self.radius
        turn = element_turn_rev(x[:, 2], contact_length, inner_rim)
        if np.any(dug_in):  # no steady state: dug in, V = w_z = 0, the wheels turning at the set points
            x[dug_in] = 0.0
            turn[dug_in] = 0.0
            dug, _ = self._fess_outputs(
                x[dug_in], spf[dug_in], np.ones(int(dug_in.sum()), bool), rest[dug_in]
            )
            for name in ('torque', 'slip', 'sinkage', 'traction_margin'):
                getattr(sol, name)[dug_in] = getattr(dug, name)
            sol.slip[dug_in] = np.sign(spf[dug_in])
        pivot = (turn > ELEMENT_TURN_LIMIT_REV) & (not self.fess.path_law)  # a chord (eq. 6.6) test
        speed, yaw = x[:, 1] * flip, x[:, 2] * flip
        return SetpointSolution(
            speed=speed,
            yaw_rate=yaw,
            s0=x[:, 0] * flip,
            omega=sp.copy(),
            torque=sol.torque * flip[:, None],
            slip=sol.slip,
            sinkage=sol.sinkage,
            traction_margin=sol.traction_margin,
            limited=dug_in | pivot,
            reason=[
                REASON_TRACTION if d else REASON_PIVOT if p else REASON_OK
                for d, p in zip(dug_in, pivot, strict=True)
            ],
            iterations=result.iterations,
            dug_in=dug_in,
            element_turn=turn,
            contact_length=np.array(contact_length, dtype=float),
            shear_path=np.full(len(sp), self.fess.path_law),
        )

    def _fess_outputs(
        self, x: np.ndarray, spf: np.ndarray, converged: np.ndarray, rest: np.ndarray
    ) -> tuple[TwistSolution, Problem]:
        """FESS's outputs at states x (P, 3) = (s0, V, w_z) and set points spf, and their problem."""
        prob = self.fess.problem(x[:, 1], x[:, 2])
        state = np.column_stack([x[:, 0], spf])
        res = NewtonResult(state, np.zeros_like(state), converged.copy(), np.zeros(len(x), dtype=int))
        sol = _outputs(prob, res, rest)
        if not self.fess.terrain.is_rigid:  # rigid ground: _outputs' friction-ceiling test
            # a side whose wheels stand or turn against its motion over the ground is dragged
            # (|slip| = 1, the inner side of a pivot turn: issue 36): at a set point its speed is
            # held, it cannot run away, and the root is a steady state; SLIP_LIMIT stays the test
            # for the other sides
            dragged = (spf * prob.side_speed <= 0) & (prob.side_speed != 0)
            if self.fess.path_law:  # the pivot band: its inner side turns about the turning centre
                # sitting over it (|slip| -> 1 as its ground speed crosses 0); the outer side's slip
                # is the traction test (issue 36: without this a gap of set points around that
                # crossing had roots of eq. 3.19 and no answer)
                inner = np.abs(spf) < np.abs(spf[:, ::-1])
                dragged |= inner & (x[:, 1:2] > 0) & (x[:, 2:3] * (spf[:, 1:2] - spf[:, 0:1]) > 0)
            physical = np.all((np.abs(sol.slip) <= SLIP_LIMIT) | dragged, axis=1)
            sol.converged = (converged & physical | rest) & np.all(prob.loads > 0, axis=1)
        return sol, prob


def element_turn_rev(yaw: ArrayLike, contact_length: ArrayLike, inner_rim_speed: ArrayLike) -> np.ndarray:
    """The body's turn while an element crosses the slower side's contact [rev]: |w_z| xi / (v_rim 2 pi)
    (eqs. 6.3, 6.5: the time in contact is xi / v_rim), with the yaw rate w_z [rad/s], the contact
    length behind the entry xi [m] and the inner side's rim speed |omega| r [m/s]; infinite for a
    stopped side of a turning body, 0 without turning."""
    yaw_abs = np.abs(np.asarray(yaw, dtype=float))
    with np.errstate(divide='ignore', invalid='ignore'):
        turn = yaw_abs * np.asarray(contact_length, dtype=float) / np.asarray(inner_rim_speed, dtype=float)
    return np.where(yaw_abs == 0.0, 0.0, turn / (2.0 * np.pi))
