"""Coordinate stage: input ports -> normalised fitting variables.

Every robot is fitted over Cartesian *frame* coordinates (x, y[, z]) with the
servo-axis frame's vertical through the origin:

- a cylindrical target (R, theta, Z) becomes ``x - D = R cos(theta)``,
  ``y = R sin(theta)``, Z; cos and sin are integer series in ``t = theta / 2**kt``
  (even and odd, from the theta symmetry), shared by all servos;
- a Cartesian target is its own frame.

A servo polynomial uses either the normalised frame coordinates
``(c - centre) / 2**k`` ("cartesian") or, when the servo's angle does not change
under rotation about the vertical axis, the normalised squared plan radius
``rho2 = x**2 + y**2`` plus the remaining coordinates ("radial"), which turns a
3-D fit into a 2-D one. Scale factors are powers of two, so normalising is wiring.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .horner import horner, lower_poly
from .plan import PlanBuilder, signed_bits
from .polyfit import fit_lawson, total_degree_terms, vander
from .ports import plan_inputs

__all__ = ["FEATURE_GRID_ENTRIES", "TRIG_TABLE_CELLS", "Cut", "CutGrid", "FeatureCut", "TrigSeries", "TrigTable", "fit_trig", "fit_trig_table", "pow2_scale", "Normaliser",
           "CylindricalStage", "CartesianStage", "coordinate_stage"]


#: table entries (fit.table_entries) from which cells of computed features are tried
#: (fit/search.py) and a cylindrical stage's cos/sin tables may be as long (of a lower degree)
FEATURE_GRID_ENTRIES = 64
#: cells of theta a cos/sin table has at most below that
TRIG_TABLE_CELLS = 32


def pow2_scale(half_range: float) -> int:
    """Smallest k >= 0 with 2**k >= half_range."""
    return max(0, math.ceil(math.log2(half_range))) if half_range > 0 else 0


@dataclass(frozen=True)
class Cut:
    """Cells of 2**shift integers of input port ``port`` (from its lowest value); variable
    ``var`` of the polynomial is the offset inside the cell, normalised to [-1, 1) (None: the
    port is no variable of the polynomial, the cells only select its coefficients)."""
    var: int | None
    port: str
    shift: int
    cells: int

    @property
    def cuts(self) -> tuple["Cut", ...]:
        return (self,)

    @property
    def entries(self) -> int:
        """Entries of a coefficient table (one per cell)."""
        return self.cells

    def table(self, values) -> tuple:
        """A coefficient's table from its values per cell (cell order: the same)."""
        return tuple(values)

    def rows(self, port, values, cell: int) -> tuple[np.ndarray, np.ndarray]:
        """Rows of real input values of ``port`` (a PlanInput) that cell ``cell`` is fitted on,
        and their normalised offsets from the cell. The last cell, which may hold fewer port
        values, is fitted on the last full cell width of the range (offsets below -1), so its
        polynomial is never fitted on a sliver."""
        u = np.asarray(values, dtype=np.float64) * 2.0 ** port.frac - port.lo
        width, top = 2 ** self.shift, port.hi - port.lo
        start = min(cell * width, max(0, top + 1 - width))
        sel = np.flatnonzero((u >= start) & (u <= min((cell + 1) * width, top)))
        half = width / 2
        return sel, (u[sel] - cell * width - half) / half

    def build(self, b: PlanBuilder, port) -> tuple[int, int]:
        """(cell, offset) nodes: the offset has ``shift - 1`` fractional bits, in [-1, 1)."""
        node = b.input_nodes[port.name]
        if port.lo:
            node = b.add(node, b.const(-port.lo * 2.0 ** -port.frac, port.frac))
        u = b.reinterpret(node, 0)
        cell, off = b.cell(u, self.shift)
        f = self.shift - 1
        return cell, b.add(b.reinterpret(off, f), b.const(-1.0, f))

    def locate(self, b: PlanBuilder, ports: dict, feats) -> tuple[int, int]:
        """(cell, offset) nodes on ``b`` (:meth:`build` of the port); ``ports``: PlanInputs by name."""
        return self.build(b, ports[self.port])

    def address(self, b: PlanBuilder, ports: dict, feats=None) -> tuple[int, list[int]]:
        """(table address, offset node per cut) on ``b``; ``ports``: PlanInputs by name,
        ``feats``: the polynomial's variable nodes (read by a :class:`FeatureCut` only)."""
        cell, off = self.locate(b, ports, feats)
        return cell, [off]


@dataclass(frozen=True)
class FeatureCut:
    """Cells of a computed variable of the polynomial (a feature such as the normalised rho2,
    in [-1, 1)): variable ``var`` (named ``name``) cut into ``2**(bits + 1)`` cells of width
    ``2**-bits``, cell m = [-1 + m 2**-bits, -1 + (m + 1) 2**-bits), and replaced by the
    offset inside its cell, normalised to [-1, 1). The hardware cuts the feature as rounded to
    the plan's feature bits, so near an edge it may take the neighbour cell; the certifier
    encloses both cases (:mod:`ikseries.fit.cut`)."""
    var: int
    name: str
    bits: int

    port = None                      # no input port: a grid's two cuts are told apart by ``var``
    address = Cut.address

    @property
    def cuts(self) -> tuple["FeatureCut", ...]:
        return (self,)

    @property
    def cells(self) -> int:
        return 2 ** (self.bits + 1)

    @property
    def entries(self) -> int:
        return self.cells

    def table(self, values) -> tuple:
        return tuple(values)

    def position(self, values) -> np.ndarray:
        """Exact feature ``values`` in cell widths from -1: cell m holds [m, m + 1)."""
        return (np.asarray(values, dtype=np.float64) + 1.0) * 2.0 ** self.bits

    def offsets(self, values, cell: int) -> tuple[np.ndarray, np.ndarray]:
        """Rows of exact feature ``values`` in cell ``cell`` (the edges' own cells: the last
        holds the range's top) and their normalised offsets from the cell."""
        u = self.position(values)
        sel = np.flatnonzero(np.clip(np.floor(u), 0, self.cells - 1) == cell)
        return sel, 2.0 * (u[sel] - cell) - 1.0

    def locate(self, b: PlanBuilder, ports: dict, feats) -> tuple[int, int]:
        """(cell, offset) nodes of feature node ``feats[var]`` (``fv`` fractional bits, at
        least ``bits + 1``): the value plus one, clamped into [0, 2) (interval analysis may
        widen the feature's range past it; the true values stay inside), cut every
        ``2**(fv - bits)`` integers."""
        node = feats[self.var]
        fv = b.frac(node)
        if fv <= self.bits:
            raise ValueError(f"a feature cut of {2 ** -self.bits:g} needs more than {self.bits} "
                             f"fractional bits of its feature, not {fv}")
        u = b.clamp(b.add(node, b.const(1.0, fv)), 0, 2 ** (fv + 1) - 1)
        shift = fv - self.bits
        cell, off = b.cell(b.reinterpret(u, 0), shift)
        return cell, b.add(b.reinterpret(off, shift - 1), b.const(-1.0, shift - 1))


@dataclass(frozen=True)
class CutGrid:
    """Cells over two input ports: cell (i, j) is cell i of cut ``a`` and cell j of cut ``b``,
    numbered ``i * b.cells + j``. Its coefficient table is addressed by the concatenation of
    both cell numbers, ``i * 2**bits + j`` (``bits`` those of b's largest cell number): a shift
    and an add of the two index nodes, no product; the ``2**bits - b.cells`` unused entries
    after each row but the last repeat the row's last entry (so no table interval widens)."""
    a: Cut
    b: Cut

    def __post_init__(self):
        if self.a.port is not None and self.a.port == self.b.port:
            raise ValueError(f"a cut grid needs two ports, not {self.a.port!r} twice")
        if self.a.var is not None and self.a.var == self.b.var:
            raise ValueError(f"a cut grid needs two variables, not variable {self.a.var} twice")

    @property
    def cuts(self) -> tuple[Cut, Cut]:
        return (self.a, self.b)

    @property
    def cells(self) -> int:
        return self.a.cells * self.b.cells

    @property
    def bits(self) -> int:
        return (self.b.cells - 1).bit_length()

    @property
    def entries(self) -> int:
        return (self.a.cells - 1) * 2 ** self.bits + self.b.cells

    def table(self, values) -> tuple:
        """A coefficient's table, in address order, from its values in cell order."""
        nb, row = self.b.cells, 2 ** self.bits
        out = []
        for i in range(self.a.cells):
            vals = list(values[i * nb:(i + 1) * nb])
            out += vals + ([vals[-1]] * (row - nb) if i < self.a.cells - 1 else [])
        return tuple(out)

    def address(self, b: PlanBuilder, ports: dict, feats=None) -> tuple[int, list[int]]:
        """(table address, [offset in a's cell, offset in b's cell]) nodes on ``b``."""
        ia_, oa = self.a.locate(b, ports, feats)
        ib, ob = self.b.locate(b, ports, feats)
        if self.bits:      # i * 2**bits: the same integer read with -bits fractional bits, widened
            ia_ = b.align(b.reinterpret(ia_, -self.bits), 0)
        return b.add(ia_, ib), [oa, ob]


@dataclass(frozen=True)
class TrigSeries:
    """cos(theta) ~ C(t**2), sin(theta) ~ t * S(t**2) with t = theta_deg / 2**kt."""
    kt: int
    cos_coeffs: tuple[float, ...]   # in powers of t**2
    sin_coeffs: tuple[float, ...]
    max_error: float                # max |series - exact| over the theta range (sampled)


def fit_trig(theta_min: float, theta_max: float, tol: float) -> TrigSeries:
    """Lowest-degree cos/sin series over [theta_min, theta_max] with error <= tol."""
    kt = pow2_scale(max(abs(theta_min), abs(theta_max)))
    th = np.linspace(theta_min, theta_max, 8001)
    t = th / 2.0 ** kt
    pts = t[:, None]
    out = []
    for kind, target, parity in (("cos", np.cos(np.radians(th)), "even"),
                                 ("sin", np.sin(np.radians(th)), "odd")):
        for deg in range(1, 40):
            terms = [e for e in total_degree_terms(deg, [parity]) if parity == "even" or e[0] % 2]
            c, err = fit_lawson(vander(pts, terms), target, 15)
            if err <= tol:
                break
        else:
            raise RuntimeError(f"no {kind} series reaches {tol:g}")
        out.append((tuple(float(x) for x in c), err))
    return TrigSeries(kt, out[0][0], out[1][0], max(out[0][1], out[1][1]))


@dataclass(frozen=True)
class TrigTable:
    """cos(theta), sin(theta) per cell of the theta port (``cut``): polynomials of ``degree``
    in the offset inside the cell (normalised to [-1, 1)); ``cos[k][c]`` is the coefficient
    of offset**k in cell c."""
    cut: Cut
    degree: int
    cos: tuple[tuple[float, ...], ...]
    sin: tuple[tuple[float, ...], ...]
    max_error: float


def fit_trig_table(port, tol: float, max_degree: int = 5, max_cells: int = TRIG_TABLE_CELLS,
                   min_degree: int = 2) -> TrigTable | None:
    """The lowest degree (``min_degree`` to ``max_degree``), then the coarsest cells (<=
    ``max_cells``: on cylinder-leg 32 gives cubics on 23 cells, whose tables take a folded core
    to 23 of the iCE40 reference part's block RAMs; 64 cells of quadratics took 32), of the
    theta port ``port`` (a PlanInput in degrees) whose per-cell near-minimax cos/sin
    polynomials stay within ``tol``; None if none does. The last cell is fitted on a full cell
    width, as :meth:`Cut.rows` defines."""
    span = port.hi - port.lo
    for degree in range(min_degree, max_degree + 1):
        for shift in range(max(1, span.bit_length() - 2), 0, -1):
            cut = Cut(0, port.name, shift, (span >> shift) + 1)
            if cut.cells > max_cells:
                break
            terms = [(k,) for k in range(degree + 1)]
            coefs, err = {"cos": [], "sin": []}, 0.0
            for c in range(cut.cells):
                width = 2 ** shift
                u = np.linspace(c * width, (c + 1) * width, 257)
                u = u[u <= span] if c < cut.cells - 1 else np.linspace(span + 1 - width, span, 257)
                sel, off = cut.rows(port, (u + port.lo) * 2.0 ** -port.frac, c)
                th = np.radians((u[sel] + port.lo) * 2.0 ** -port.frac)
                for name, f in (("cos", np.cos), ("sin", np.sin)):
                    cf, e = fit_lawson(vander(off[:, None], terms), f(th), 20)
                    coefs[name].append(cf)
                    err = max(err, float(e))
            if err <= tol:
                return TrigTable(cut, degree, *(tuple(tuple(float(v) for v in np.array(coefs[k])[:, j])
                                                      for j in range(degree + 1)) for k in ("cos", "sin")), err)
    return None


@dataclass(frozen=True)
class Normaliser:
    """``(value - centre) / 2**shift``: centre on the value's grid, power-of-two scale."""
    centre: float
    shift: int

    @classmethod
    def for_range(cls, lo: float, hi: float, grid_frac: int | None = None) -> "Normaliser":
        """Centre 0 for a range symmetric about 0 (so parity can be used), else the midpoint
        (rounded to the ``grid_frac`` grid if given)."""
        if lo == -hi:
            c = 0.0
        else:
            c = (lo + hi) / 2
            if grid_frac is not None:
                c = round(c * 2 ** grid_frac) / 2 ** grid_frac
        return cls(float(c), pow2_scale(max(hi - c, c - lo)))

    def __call__(self, v):
        return (np.asarray(v, dtype=np.float64) - self.centre) * 2.0 ** -self.shift

    def build(self, b: PlanBuilder, node: int, fv: int) -> int:
        """Normalised ``node`` with ``fv`` fractional bits."""
        if self.centre:
            node = b.add(node, b.const(-self.centre, b.frac(node)))
        return b.align(b.reinterpret(node, b.frac(node) + self.shift), fv)

    def meta(self) -> dict:
        return {"centre": self.centre, "shift": self.shift}


class _Stage:
    """Shared behaviour: frame coordinates, their normalisers and the radial feature."""

    names: tuple[str, ...]
    norms: tuple[Normaliser, ...]
    rho2_norm: Normaliser | None

    def exact(self, *inputs) -> np.ndarray:
        """Normalised frame coordinates (N, n) with exact arithmetic (what the fit targets)."""
        return np.stack([nm(c) for nm, c in zip(self.norms, self.frame(*inputs))], 1)

    def rho2(self, *inputs) -> np.ndarray:
        x, y = self.frame(*inputs)[:2]
        return x * x + y * y

    def exact_radial(self, *inputs) -> np.ndarray:
        """Normalised (rho2, remaining frame coordinates...) (N, n - 1)."""
        f = self.frame(*inputs)
        cols = [self.rho2_norm(f[0] * f[0] + f[1] * f[1])]
        cols += [nm(c) for nm, c in zip(self.norms[2:], f[2:])]
        return np.stack(cols, 1)

    @property
    def has_plan_axes(self) -> bool:
        return self.names[:2] == ("x", "y")

    def _rho2_normaliser(self, robot) -> Normaliser | None:
        if not self.has_plan_axes:
            return None
        axes = [np.linspace(i.min, i.max, 65) for i in robot.workspace.inputs]
        grid = [g.ravel() for g in np.meshgrid(*axes, indexing="ij")]
        r2 = self.rho2(*grid)
        return Normaliser.for_range(float(r2.min()), float(r2.max()))

    def build_radial(self, b: PlanBuilder, fv: int) -> list[int]:
        """Nodes of the radial features (after :meth:`build` on the same builder)."""
        rho2 = self._rho2_node(b)
        return [self.rho2_norm.build(b, rho2, fv), *self._normalised[2:]]

    def base_meta(self) -> dict:
        return {"names": list(self.names), "normalisers": [n.meta() for n in self.norms],
                "rho2": self.rho2_norm.meta() if self.rho2_norm else None}


class CylindricalStage(_Stage):
    """Frame (x, y, z) of a cylindrical target (R, theta, Z) around the neutral point at
    distance D: x = D + R cos(theta), y = R sin(theta)."""

    kind = "cylindrical"
    names = ("x", "y", "z")

    def __init__(self, robot, trig_tol: float, table: bool = False):
        g = robot.geometry
        r, th, z = robot.workspace.inputs
        self.geometry = g
        self.offset = g.neutral_distance
        self.trig = fit_trig(th.min, th.max, trig_tol)
        port = next(i for i in plan_inputs(robot) if i.name == "theta")
        # where the description allows long tables, lines on many cells (fewer products, shallower)
        entries = robot.fit.table_entries
        long = entries >= FEATURE_GRID_ENTRIES
        self.long = long and table
        self.table = fit_trig_table(port, trig_tol, max_cells=entries if long else TRIG_TABLE_CELLS,
                                    min_degree=1 if long else 2) if table else None
        kx = pow2_scale(r.max)
        self.norms = (Normaliser(self.offset, kx), Normaliser(0.0, kx),
                      Normaliser.for_range(z.min, z.max, z.frac_bits))
        self.rho2_norm = self._rho2_normaliser(robot)

    def frame(self, r, theta, z):
        return self.geometry.to_cartesian(r, theta, z)

    def ik_frame(self, x, y, z):
        return self.geometry.ik_cartesian(x, y, z)

    def build(self, b: PlanBuilder, fv: int, fc: int, mixed: bool = False) -> list[int]:
        """Add the coordinate stage to ``b``: normalised (x, y, z) with ``fv`` fractional bits.

        ``fc`` is the fractional precision of t**2, cos and sin; ``mixed``: the series by the
        Horner/Estrin mix of least depth (at most 2 extra multiplications each), else Horner.
        Call before :meth:`build_radial` on the same builder.
        """
        rn, thn, zn = (b.input_nodes[n] for n in ("r", "theta", "z"))
        if self.table is not None:     # per cell of theta: polynomials in the offset, table coefficients
            tab = self.table
            port = next(i for i in b.inputs if i.name == "theta")
            cell, off = tab.cut.build(b, port)
            off = b.align(off, max(fc, b.frac(off)))

            def table(coeffs):
                return lower_poly(b, {(k,): c for k, c in enumerate(coeffs)}, [off], fc,
                                  lambda v, f: b.lut(cell, v, f), max_extra_muls=2, guard=4)
            cos, sin = table(tab.cos), table(tab.sin)
            trig_error = tab.max_error
        else:
            t = b.reinterpret(thn, b.frac(thn) + self.trig.kt)
            u = b.mul(t, t, fc)

            def series(coeffs):
                poly = {(k,): c for k, c in enumerate(coeffs)}
                return lower_poly(b, poly, [u], fc, max_extra_muls=2, guard=4) if mixed else horner(b, poly, [u], fc)
            cos = series(self.trig.cos_coeffs)
            sin = b.mul(t, series(self.trig.sin_coeffs), fc)
            trig_error = self.trig.max_error
        # Interval arithmetic on a Horner chain overestimates |cos| and |sin| ~10x, which
        # the servo polynomials would raise to the 8th power. Clamping to the true range
        # (plus the series error, so the clamp never moves a value away from the ideal)
        # keeps every later width tight.
        # Built for depth, a clamp that saves no bit (long tables' lines overshoot by a few
        # per cent at most) is left out: it would add pipeline stages on the longest path.
        lim = int(np.ceil((1.0 + max(1.5 * trig_error, 2.0 ** -10)) * 2 ** fc))
        cos, sin = (v if self.long and b.signed_width(v) <= signed_bits(-lim, lim) else b.clamp(v, -lim, lim)
                    for v in (cos, sin))
        self._r, self._cos = rn, cos
        self._rcos = b.mul(rn, cos)
        rsin = b.mul(rn, sin)
        kx = self.norms[0].shift
        self._normalised = [b.align(b.reinterpret(p, b.frac(p) + kx), fv) for p in (self._rcos, rsin)]
        self._normalised.append(self.norms[2].build(b, zn, fv))
        return list(self._normalised)

    def _rho2_node(self, b: PlanBuilder) -> int:
        # rho2 = R**2 + 2 D R cos(theta) + D**2: needs no sine, so the radial servos'
        # cones skip the sine series.
        r2 = b.mul(self._r, self._r)
        cf = 0 if float(2 * self.offset).is_integer() else 12
        if self.long:    # built for depth: 2 D R (from the input) times cos, beside R cos
            twod = b.mul(b.mul(self._r, b.const(2 * self.offset, cf)), self._cos)
        else:
            twod = b.mul(self._rcos, b.const(2 * self.offset, cf))
        f = b.frac(twod)
        acc = b.add(b.align(r2, f), twod)
        return b.add(acc, b.const(self.offset ** 2, f))

    def meta(self) -> dict:
        if self.table is not None:
            t = self.table
            return {"kind": self.kind, **self.base_meta(),
                    "trig_table": {"input": t.cut.port, "cells": t.cut.cells,
                                   "port_values_per_cell": 2 ** t.cut.shift, "degree": t.degree,
                                   "cos": [list(c) for c in t.cos], "sin": [list(c) for c in t.sin],
                                   "max_error": t.max_error}}
        return {"kind": self.kind, **self.base_meta(),
                "trig": {"kt": self.trig.kt, "cos": list(self.trig.cos_coeffs),
                         "sin": list(self.trig.sin_coeffs), "max_error": self.trig.max_error}}

    def describe(self) -> str:
        if self.table is not None:
            t = self.table
            return (f"coordinate stage: cos/sin per cell of theta ({t.cut.cells} cells of "
                    f"{2 ** t.cut.shift} port values), degree {t.degree}, max error {t.max_error:.2e}")
        return (f"coordinate stage: cos/sin series of degree {2 * len(self.trig.cos_coeffs) - 2} / "
                f"{2 * len(self.trig.sin_coeffs) - 1}, max error {self.trig.max_error:.2e}")


class CartesianStage(_Stage):
    """A Cartesian target is its own frame; normalising is a constant add and wiring."""

    kind = "cartesian"

    def __init__(self, robot):
        self.geometry = robot.geometry
        self.names = tuple(i.name for i in robot.workspace.inputs)
        self.norms = tuple(Normaliser.for_range(i.min, i.max, i.frac_bits) for i in robot.workspace.inputs)
        self.rho2_norm = self._rho2_normaliser(robot)

    def frame(self, *inputs):
        return tuple(np.asarray(v, dtype=np.float64) for v in inputs)

    def ik_frame(self, *coords):
        return self.geometry.ik(*coords)

    def build(self, b: PlanBuilder, fv: int, fc: int, mixed: bool = False) -> list[int]:
        self._inputs = [b.input_nodes[n] for n in self.names]
        self._normalised = [nm.build(b, n, fv) for nm, n in zip(self.norms, self._inputs)]
        return list(self._normalised)

    def _rho2_node(self, b: PlanBuilder) -> int:
        x, y = self._inputs[:2]
        return b.add(b.mul(x, x), b.mul(y, y))

    def meta(self) -> dict:
        return {"kind": self.kind, **self.base_meta()}

    def describe(self) -> str:
        return "coordinate stage: Cartesian inputs (normalising only)"


def coordinate_stage(robot, trig_tol: float, table: bool = False):
    """The coordinate stage for ``robot``'s kind of target; ``table``: a cylindrical target's
    cos/sin from per-cell tables of theta (:class:`TrigTable`, shallower) when one meets
    ``trig_tol``, else series."""
    if getattr(robot.geometry, "coordinates", "cartesian") == "cylindrical":
        return CylindricalStage(robot, trig_tol, table)
    return CartesianStage(robot)
