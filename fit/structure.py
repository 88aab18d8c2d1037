"""The structure of one servo polynomial: its variables, their symmetries, its terms.

:class:`FeatureSet` names the variables a servo is fitted over and the powers each may take;
:func:`feature_sets` proposes the candidates for a servo from a numerical analysis of its
reference pulses (:func:`analyse`). :class:`ServoFit` is the immutable result of fitting one.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..kinematics import UnreachableError
from .features import Cut, CutGrid, FeatureCut, Normaliser
from .plan import bits_for, quantize
from .polyfit import total_degree_terms

__all__ = ["FeatureSet", "ServoFit", "analyse", "feature_sets", "input_norms", "feature_values", "FIT_SEED"]

FIT_SEED = 20261124


@dataclass(frozen=True)
class FeatureSet:
    """The variables one servo polynomial is fitted over.

    ``kind``: "radial" (normalised rho2 = x**2 + y**2, then the remaining frame
    coordinates), "cartesian" (normalised frame coordinates) or "direct" (normalised
    input ports, e.g. R, theta, Z as in the integer power series paper).
    ``allowed[k]``: any / even / odd / none powers of variable k. ``zero_free``: index of
    an odd variable whose zero-power terms vanish except the constant (the servo value
    on that variable's zero plane is constant), or None.
    """
    kind: str
    names: tuple
    allowed: tuple
    zero_free: int | None = None
    tensor: bool = False      # every power up to ``degree`` per variable, not total degree
    cut: "Cut | FeatureCut | CutGrid | None" = None  # piecewise: cells of one port or feature, or a grid over two

    def label(self) -> str:
        return f"{self.kind} {'/'.join(self.names)}" + self.extras()

    def structure(self) -> str:
        """Kind, term set and cells, e.g. ``radial, 3 cells in z`` (for reports)."""
        return self.kind + self.extras().replace(" tensor", ", tensor terms")

    def piecewise_record(self) -> dict | None:
        """JSON-ready description of the cells (None if not piecewise): per cut port its
        variable (None if the port is no variable), cells and port values per cell; a grid also
        its table entries and address (``cell_a * 2**bits + cell_b``)."""
        if self.cut is None:
            return None
        rec = [self._cut_record(c) for c in self.cut.cuts]
        if not isinstance(self.cut, CutGrid):
            return rec[0]
        return {"grid": rec, "cells": self.cut.cells, "table_entries": self.cut.entries,
                "address_bits_b": self.cut.bits}

    def _cut_record(self, c) -> dict:
        if isinstance(c, FeatureCut):      # cells of a computed variable, normalised to [-1, 1)
            return {"feature": c.name, "variable": c.name, "cells": c.cells, "cell_width": 2.0 ** -c.bits}
        return {"input": c.port, "variable": None if c.var is None else self.names[c.var], "cells": c.cells,
                "port_values_per_cell": 2 ** c.shift}

    def extras(self) -> str:
        if self.cut is None:
            cells = ""
        elif isinstance(self.cut, CutGrid):
            a, b = self.cut.a, self.cut.b
            cells = f", {a.cells}x{b.cells} cells in {a.port or a.name} x {b.port or b.name}"
        else:
            cells = f", {self.cut.cells} cells in {self.cut.port or self.cut.name}"
        return (" tensor" if self.tensor else "") + cells

    def feature_piecewise(self, var: int, bits: int, second: tuple | None = None) -> "FeatureSet":
        """The same variables with variable ``var`` (a computed feature) cut into cells of
        ``2**-bits`` (:class:`FeatureCut`), its powers "any"; ``second`` = (var, port, cells)
        of a port or (var, bits) of another feature: a grid over both."""
        cut = FeatureCut(var, self.names[var], bits)
        fs = self._any(var)
        if second is None:
            return dataclasses.replace(fs, cut=cut)
        if len(second) == 2:
            fs, cut_b = fs._any(second[0]), FeatureCut(second[0], self.names[second[0]], second[1])
        else:
            fs, cut_b = fs._cut_one(*second)
        return dataclasses.replace(fs, cut=CutGrid(cut, cut_b))

    def _any(self, var: int) -> "FeatureSet":
        return dataclasses.replace(self, allowed=self.allowed[:var] + ("any",) + self.allowed[var + 1:],
                                   zero_free=None if self.zero_free == var else self.zero_free)

    def piecewise(self, var: int | None, port, cells: int, second: tuple | None = None) -> "FeatureSet":
        """The same variables cut into ``cells`` equal cells of the integer range of input
        ``port``: variable ``var`` (the normalised port; None if the port is no variable)
        becomes the offset inside the cell, which has no symmetry, so its powers are "any".
        ``second`` = (var, port, cells): a grid over both ports (:class:`CutGrid`)."""
        fs, cut = self._cut_one(var, port, cells)
        if second is None:
            return dataclasses.replace(fs, cut=cut)
        fs, cut_b = fs._cut_one(*second)
        return dataclasses.replace(fs, cut=CutGrid(cut, cut_b))

    def _cut_one(self, var, port, cells) -> tuple["FeatureSet", Cut]:
        per = -(-(port.hi - port.lo + 1) // cells)          # port values per cell, rounded up
        shift = max(1, (per - 1).bit_length())
        fs = self if var is None else self._any(var)
        return fs, Cut(var, port.name, shift, ((port.hi - port.lo) >> shift) + 1)

    def terms(self, degree: int) -> list:
        if self.tensor:
            terms = [e for e in total_degree_terms(degree * len(self.allowed), list(self.allowed))
                     if max(e, default=0) <= degree]
        else:
            terms = total_degree_terms(degree, list(self.allowed))
        if self.zero_free is not None:
            k = self.zero_free
            terms = [e for e in terms if e[k] > 0 or sum(e) == 0]
        return terms


@dataclass(frozen=True)
class ServoFit:
    """One servo's fitted polynomial (immutable: each fit step returns a new one)."""
    name: str
    features: FeatureSet     # the variables and their allowed powers
    degree: int
    poly: dict               # {exponents: float coefficient} over the features (ticks)
    fit_error_ticks: float   # max error on the fit and check samples (float coefficients)
    frac: int = 0            # accumulator / coefficient fractional bits
    bound_pu: float = 0.0    # certified rounding bound
    # fit data for the refit after quantization: (Cells, per cell MinimaxFit (active rows), budget)
    refit: tuple | None = field(default=None, repr=False, compare=False)

    def integers(self) -> dict:
        """{exponents: coefficient integer on the 2**-frac grid} (a tuple per cell if piecewise)."""
        q = lambda c: quantize(c, self.frac)  # noqa: E731
        return {e: tuple(map(q, c)) if isinstance(c, tuple) else q(c) for e, c in self.poly.items()}

    def coefficient_bits(self) -> int:
        """Widest coefficient integer (two's complement bits)."""
        ints = np.ravel(list(self.integers().values()))
        return max(bits_for(min(0, int(q)), max(0, int(q)))[0] for q in ints)


def analyse(f, coords: list, norms, names, kind: str) -> FeatureSet:
    """Parity and dependence of ``f`` (pulses of one servo) in each coordinate, numerically.

    Parity is only usable for a coordinate normalised about 0: "even" if
    f(..., -c, ...) = f(..., c, ...), "odd" if f(c) + f(-c) = 2 f(0). A target
    that the reflection makes unreachable means "any".
    """
    p0 = f(*coords)
    eps = 1e-9 * max(1.0, float(np.ptp(p0)))
    allowed, zero_free = [], None
    for k, (c, nm) in enumerate(zip(coords, norms)):
        def at(v):
            cc = list(coords)
            cc[k] = v
            try:
                return f(*cc)
            except UnreachableError:
                return None
        lo, hi = at(np.full_like(c, c.min())), at(np.full_like(c, c.max()))
        if lo is not None and hi is not None and np.max(np.abs(lo - hi)) < eps \
                and np.max(np.abs(lo - p0)) < eps:
            allowed.append("none")
            continue
        par = "any"
        if nm.centre == 0:
            pm, pz = at(-c), at(0 * c)
            if pm is not None and np.max(np.abs(pm - p0)) < eps:
                par = "even"
            elif pm is not None and pz is not None and np.max(np.abs(p0 + pm - 2 * pz)) < eps:
                par = "odd"
                if zero_free is None and np.ptp(pz) < eps:
                    zero_free = k
        allowed.append(par)
    return FeatureSet(kind, tuple(names), tuple(allowed), zero_free)


def feature_sets(ctx, k: int) -> list[FeatureSet]:
    """Candidate variable sets for servo ``k`` of ``ctx.robot``, cheapest-looking first."""
    robot, stage = ctx.robot, ctx.stage
    rng = np.random.default_rng(FIT_SEED + k)
    n = 2000
    pts = [i.min + (i.max - i.min) * rng.random(n) for i in robot.workspace.inputs]
    cal = robot.joint_calibration
    fk = lambda *c: cal.pulses(stage.ik_frame(*c))[k]  # noqa: E731
    frame = list(stage.frame(*pts))
    cartesian = analyse(fk, frame, stage.norms, stage.names, "cartesian")
    out = []
    if stage.has_plan_axes:
        rho = np.hypot(frame[0], frame[1])
        p0 = fk(*frame)
        try:
            radial = np.max(np.abs(fk(rho, 0 * rho, *frame[2:]) - p0)) < 1e-9 * max(1.0, float(np.ptp(p0)))
        except UnreachableError:
            radial = False
        if radial:
            out.append(FeatureSet("radial", ("rho2", *stage.names[2:]), ("any", *cartesian.allowed[2:])))
    out.append(cartesian)
    if stage.kind != "cartesian":
        fi = lambda *c: robot.pulses_pu(*c)[k]  # noqa: E731
        out.append(analyse(fi, pts, input_norms(robot), [i.name for i in robot.workspace.inputs], "direct"))
    # the same variables with tensor-product terms (a per-variable degree) where that differs
    out += [dataclasses.replace(fs, tensor=True) for fs in list(out)
            if sum(a != "none" for a in fs.allowed) > 1]
    return out


def input_norms(robot) -> list:
    """The normalisers of the robot's input ports (the "direct" variables)."""
    return [Normaliser.for_range(i.min, i.max, i.frac_bits) for i in robot.workspace.inputs]


def feature_values(ctx, kind: str, pts) -> np.ndarray:
    """Exact feature values (N, n) of ``kind`` at real input points."""
    if kind == "radial":
        return ctx.stage.exact_radial(*pts)
    if kind == "cartesian":
        return ctx.stage.exact(*pts)
    return np.stack([nm(v) for nm, v in zip(input_norms(ctx.robot), pts)], 1)
