"""A holding law next to the paper's (beyond the paper; docs/holding.md, "A law that holds",
eqs. (H1)-(H8)).

The paper's law (eq. (19)) places the arm relative to the object, wherever the object is; this
law wraps the object without touching it, then holds a shape anchored at the arm's base:
**cage** (H1, eq. (19) with ``rho_d = r + g``), **close** (H2, the gap ``g`` shrinks once the
wrap angle (H3) reaches ``wrap_angle``), **hold** (H4)-(H6: the latched curvature as an elastic
rod's rest curvature, moved to the parallel curve (H5) pressing ``squeeze`` deep; a potential,
energy (H6)), optionally **dwell** (H8) and **depth regulation** (H7). It senses ``(rho, alpha)``
(eq. (4)) and the arm's own curvature, never the object's pose.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import ClassVar, Protocol

import numpy as np
from numpy.typing import NDArray

from contgrasp_core.control.gains import FeedbackGains
from contgrasp_core.control.law import CENTIMETRE, adaptive_mu2
from contgrasp_core.errors import InvalidParameterError, refuse_ignored
from contgrasp_core.rod.model import RodModel
from contgrasp_core.rod.validity import PENETRATION_LIMIT

__all__ = ["LAWS", "HOLDING_LAWS", "HoldLawSettings", "check_law_settings", "ShapeHold", "PaperLaw", "HoldController", "Law", "wrap_angle",
           "parallel_curvature", "cage_gains"]

Array = NDArray[np.float64]

LAWS = ("paper", "hold", "reactive")
"""The closed loop's laws: the paper's eq. (19); ``hold``, the planned hold
(:class:`contgrasp_core.holding.plan.PlannedHold`: this module's holding law run first on the
object held fixed, its path of shapes played back, docs/holding.md); ``reactive``, this
module's holding law on what the arm senses (:class:`HoldController`, its planner)."""

HOLDING_LAWS = ("hold", "reactive")
"""The laws that hold (docs/holding.md): both take the holding law's settings (``hold`` through its planner)."""


@dataclass(frozen=True)
class HoldLawSettings:
    """The holding law's parameters (SI; module docstring): the cage's ``clearance`` (m, the
    gap ``g`` of (H1)), ``band`` (m: nodes within ``g + band`` of the object's surface form the
    enclosing band of (H3)), the ``wrap_angle`` (rad) that starts the close, the ``close_rate``
    (m/s) and the ``close_gap`` (m) at which the shape is latched, the ``squeeze`` depth (m)
    and the ``squeeze_time`` (s) of (H5), the hold's stiffness gain ``stiffness_gain`` (G of
    (H4), dimensionless), the paper's ``mu1``, the ``depth_gain`` (1/s) of the depth
    regulation (H7; 0, the default: none, the squeeze of (H5) as latched) and the ``dwell`` (s)
    over which the latch averages the cage's curvature (H8; 0, the default: one sample); the
    planned hold's playback (law ``hold``): its stiffness ``plan_gain`` (G, dimensionless), the
    stiffness of its damper ``plan_damping`` (D, dimensionless), the damper's relaxation time
    ``plan_damping_time`` (tau, s), the squeeze's depth ``plan_squeeze`` (the deepest it presses
    an element into the object, a fraction of the element's radius, below the model's 0.3; 0:
    none) and its ramp ``plan_squeeze_time`` (s) (P2)."""

    clearance: float = 0.006
    band: float = 0.001
    wrap_angle: float = float(np.pi)
    close_rate: float = 0.003
    close_gap: float = 0.0025
    squeeze: float = 0.0005
    squeeze_time: float = 1.0
    stiffness_gain: float = 3000.0
    mu1: float = 1.0
    depth_gain: float = 0.0
    dwell: float = 0.0
    plan_gain: float = 100.0
    plan_damping: float = 500.0
    plan_damping_time: float = 0.05
    plan_squeeze: float = 0.1
    plan_squeeze_time: float = 0.3

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)):
                raise InvalidParameterError(f"hold law {f.name} must be a finite number, got {v!r}")
        for name in ("clearance", "band", "close_rate", "squeeze_time", "mu1", "plan_damping_time", "plan_squeeze_time"):
            if getattr(self, name) <= 0:
                raise InvalidParameterError(f"hold law {name} must be > 0, got {getattr(self, name)!r}")
        for name in ("squeeze", "stiffness_gain", "depth_gain", "dwell", "plan_gain", "plan_damping"):
            if getattr(self, name) < 0:
                raise InvalidParameterError(f"hold law {name} must be >= 0, got {getattr(self, name)!r}")
        if not 0 < self.close_gap < self.clearance:
            raise InvalidParameterError(f"hold law close_gap must be in (0, clearance = {self.clearance!r}) m, "
                                        f"got {self.close_gap!r}")
        if not 0 <= self.plan_squeeze < PENETRATION_LIMIT:
            raise InvalidParameterError(f"hold law plan_squeeze must be in [0, {PENETRATION_LIMIT}) (of an element's radius: "
                                        f"the model holds to {PENETRATION_LIMIT}), got {self.plan_squeeze!r}")
        if not np.pi <= self.wrap_angle < 2 * np.pi:
            raise InvalidParameterError(f"hold law wrap_angle must be in [pi, 2 pi) rad (a cage surrounds more than "
                                        f"half of the object), got {self.wrap_angle!r}")


def check_law_settings(law: str, settings: HoldLawSettings, name: Callable[[str], str] = str) -> None:
    """Refuse holding-law ``settings`` other than the defaults under a ``law`` that ignores them:
    the paper's ignores all, ``reactive`` the playback's ``plan_*`` (``hold`` uses all: its
    planner is the reactive law; :func:`~contgrasp_core.errors.refuse_ignored`); ``name`` gives a
    setting's name (and ``law``'s) as the caller knows it, e.g. a command-line option."""
    if law in ("paper", "reactive"):
        changed = [f.name for f in fields(settings) if getattr(settings, f.name) != f.default
                   and (law == "paper" or f.name.startswith("plan_"))]
        needs = "hold" if all(c.startswith("plan_") for c in changed) else "hold or reactive"
        refuse_ignored([name(c) for c in changed], f"under {name('law')} {law}", f"{name('law')} {needs}")


def wrap_angle(theta: Array, alpha: Array, band: NDArray[np.bool_]) -> float:
    """The wrap angle (H3): the turn of the object's tangent ``phi = theta + alpha - pi/2`` (eq.
    (4)) from the first to the last node of the enclosing ``band`` (N+1 booleans), summed over
    the nodes between as wrapped increments in (-pi, pi]; 0 with fewer than two band nodes."""
    idx = np.flatnonzero(band)
    if idx.size < 2:
        return 0.0
    phi = np.asarray(theta, dtype=float)[idx[0]:idx[-1] + 1] + np.asarray(alpha, dtype=float)[idx[0]:idx[-1] + 1]
    return float(np.sum(np.mod(np.diff(phi) + np.pi, 2.0 * np.pi) - np.pi))


def parallel_curvature(kappa: Array, offset: float) -> Array:
    """Curvature of the parallel curve ``offset`` (m) towards the centre of curvature (H5):
    ``kappa / (1 - offset |kappa|)`` (a circle of radius ``1/|kappa|`` becomes one of radius
    ``1/|kappa| - offset``). :class:`InvalidParameterError` where ``offset |kappa| >= 1`` (the
    parallel curve does not exist there)."""
    k = np.asarray(kappa, dtype=float)
    den = 1.0 - offset * np.abs(k)
    if np.any(den <= 0):
        raise InvalidParameterError(f"no parallel curve at offset {offset!r} m where the radius of curvature is "
                                    f"below it (largest |kappa| {float(np.abs(k).max())!r} 1/m)")
    return np.asarray(k / den, dtype=np.float64)


def cage_gains(model: RodModel, object_radius: float, settings: HoldLawSettings, gap: float,
               length_unit: float = CENTIMETRE) -> FeedbackGains:
    """The cage's gains (H1) at the gap ``gap`` (m): eq. (19) with ``mu2`` of eq. (A-2) for
    ``rho_d = r + gap`` at the rod's joints (law units, Appendix IV)."""
    return FeedbackGains(mu1=settings.mu1, length_unit=length_unit,
                         mu2=adaptive_mu2(model.radius(model.joint_s) + gap, object_radius, length_unit=length_unit))


@dataclass(frozen=True)
class ShapeHold:
    """The hold's couple (H4) at the joints: the held part ``couple = -EI kappa_ref`` (N,) and the
    state feedback ``G EI (kappa(theta) - kappa_ref)``, linear in the element angles (so its
    first-order hold is exact) with the bidiagonal Jacobian ``G EI_k / D_k`` (k, k) and
    ``-G EI_k / D_k`` (k, k-1) (``kappa_k = (theta_k - theta_{k-1}) / D_k``)."""

    model: RodModel
    kappa_ref: Array
    gain: float
    couple: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "couple", -self.model.joint_ei * self.kappa_ref)

    def couple_and_jacobian(self, theta: Array, *, jacobian: bool = True, nodes: Array | None = None,
                            normals: Array | None = None) -> tuple[Array, Array | None]:
        """``G EI (kappa - kappa_ref)`` (N,) and its derivative in ``theta`` (N, N)."""
        m = self.model
        stiffness = self.gain * m.joint_ei / m.joint_len
        u = self.gain * m.joint_ei * (m.joint_curvature(theta) - self.kappa_ref)
        if not jacobian:
            return u, None
        du = np.diag(stiffness)
        k = np.arange(1, m.n_elements)
        du[k, k - 1] = -stiffness[1:]
        return u, du


@dataclass(frozen=True)
class PaperLaw:
    """The paper's law (eq. (19)) with fixed gains, behind the same :meth:`command` as
    :class:`HoldController` (it keeps no state)."""

    fixed: FeedbackGains
    name: ClassVar[str] = "paper"

    @property
    def holding(self) -> bool:
        """Always True: the paper's law has no phases."""
        return True

    def command(self, rho: Array, alpha: Array, theta: Array, kappa: Array, period: float) -> FeedbackGains:
        """The gains, whatever is sensed."""
        return self.fixed


class HoldController:
    """The holding law's state across control periods (module docstring): ``phase`` ``cage``,
    ``close`` or ``hold``, the current gap ``gap`` (m), and in the hold the latched reference.
    :meth:`command` is called once per control period with what the arm senses; in the dwell
    (H8) the phase is ``close`` at ``gap == close_gap``."""

    name: ClassVar[str] = "reactive"

    def __init__(self, model: RodModel, object_radius: float, settings: HoldLawSettings = HoldLawSettings(),
                 length_unit: float = CENTIMETRE) -> None:
        self.model, self.settings, self.length_unit = model, settings, length_unit
        self.object_radius = float(object_radius)
        self.phase = "cage"
        self.clock = 0.0  # (the law's own time, s, and when its close started)
        self.closed_at: float | None = None
        self.gap = settings.clearance
        self.progress = 0.0
        self._radius = model.radius(model.s_nodes)
        self._kappa_star: Array | None = None
        self._kappa_step: Array | None = None
        self._on: NDArray[np.bool_] | None = None  # (the joints whose parallel curve the hold takes)
        self.depth_offset = 0.0  # (z of (H7), m)
        self._dwelt = 0.0  # (the dwell's time so far (H8), s, and its sums of the curvature and the band)
        self._kappa_sum = np.zeros(model.n_elements)
        self._band_count = np.zeros(model.n_elements)
        self._samples = 0

    @property
    def holding(self) -> bool:
        """The hold is complete: the reference has reached the squeezed shape."""
        return self.phase == "hold" and self.progress >= 1.0

    def gains(self) -> FeedbackGains:
        """Eq. (19)'s gains for the current gap (H1): :func:`cage_gains`."""
        return cage_gains(self.model, self.object_radius, self.settings, self.gap, self.length_unit)

    def command(self, rho: Array, alpha: Array, theta: Array, kappa: Array, period: float) -> FeedbackGains | ShapeHold:
        """The law for the next ``period`` (s) from ``rho``, ``alpha`` and the node angles ``theta``
        at the N+1 nodes and the curvature ``kappa`` at the N joints: eq. (19)'s gains (cage,
        close) or the hold's :class:`ShapeHold`."""
        s = self.settings
        now, self.clock = self.clock, self.clock + period
        band = np.asarray(rho, dtype=float) - self._radius <= self.gap + s.band
        if self.phase == "cage" and wrap_angle(theta, alpha, band) >= s.wrap_angle:
            self.phase, self.closed_at = "close", now
        if self.phase == "close":
            self.gap = max(self.gap - s.close_rate * period, s.close_gap)
            if self.gap <= s.close_gap and self._dwell(np.asarray(kappa, dtype=float), band[:-1], period):
                self._latch()
        if self.phase == "hold":
            assert self._kappa_star is not None and self._kappa_step is not None
            if s.depth_gain > 0 and self.progress >= 1.0:
                return self._regulated(np.asarray(rho, dtype=float), band, period)
            self.progress = min(1.0, self.progress + period / s.squeeze_time)
            return ShapeHold(self.model, self._kappa_star + self.progress * self._kappa_step, s.stiffness_gain)
        return self.gains()

    def _dwell(self, kappa: Array, band: NDArray[np.bool_], period: float) -> bool:
        """(H8): add one period's sensed curvature and band to the dwell's sums; True when the
        dwell is over (at once with ``dwell`` 0)."""
        self._kappa_sum += kappa
        self._band_count += band
        self._samples += 1
        self._dwelt += period
        return self._dwelt >= self.settings.dwell

    def _latch(self) -> None:
        """(H4), (H5): latch the dwell's mean curvature ``kappa*`` and the squeezed parallel curve
        on the joints in the band for more than half of the dwell; the phase becomes ``hold``."""
        s = self.settings
        k = self._kappa_sum / self._samples
        target = k.copy()
        offset = s.close_gap + s.squeeze
        reach = offset + (s.clearance if s.depth_gain > 0 else 0.0)  # (the largest offset (H7) may take)
        on = (2 * self._band_count > self._samples) & (reach * np.abs(k) < 1.0)  # (where the parallel curve exists)
        target[on] = parallel_curvature(k[on], offset)
        self._kappa_star, self._kappa_step, self._on = k, target - k, on
        self.phase = "hold"

    def _regulated(self, rho: Array, band: NDArray[np.bool_], period: float) -> ShapeHold:
        """(H7): the offset's integral step from the sensed contact depth on the band, and the
        held shape at the new offset."""
        s = self.settings
        assert self._kappa_star is not None and self._on is not None
        depth = self._radius - rho  # (> 0: pressed into the object)
        touching = band & (depth > 0)
        if touching.any():
            error = s.squeeze - float(depth[touching].mean())
        elif band.any():
            error = s.squeeze - float(depth[band].max())
        else:  # (nothing sensed: hold the offset)
            error = 0.0
        self.depth_offset = float(np.clip(self.depth_offset + s.depth_gain * error * period,
                                          -(s.close_gap + s.squeeze), s.clearance))
        kappa_ref = self._kappa_star.copy()
        kappa_ref[self._on] = parallel_curvature(self._kappa_star[self._on], s.close_gap + s.squeeze + self.depth_offset)
        return ShapeHold(self.model, kappa_ref, s.stiffness_gain)


class Law(Protocol):
    """A closed loop's law (:class:`PaperLaw`, :class:`HoldController`,
    :class:`contgrasp_core.holding.plan.PlannedHold`): what :meth:`command` gives for each
    control period, and whether it is ``holding`` (out of transition)."""

    name: ClassVar[str]

    @property
    def holding(self) -> bool:
        """The law is out of its transition: a rest now counts as settled."""

    def command(self, rho: Array, alpha: Array, theta: Array, kappa: Array, period: float) -> FeedbackGains | ShapeHold:
        """The command for the next ``period`` (s) from what the arm senses."""
