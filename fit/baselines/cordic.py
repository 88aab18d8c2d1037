"""CORDIC leg solver: design parameters, the datapath and its range analysis.

The conventional baseline for the polynomial design: the same inverse kinematics computed
with CORDIC stages. The datapath is written ONCE, in :func:`datapath`, against a small
operation interface (``ops``); three back ends run it:

- :class:`IntervalOps` (here): integer interval analysis. It yields the range, hence the
  width, of every pipeline register (the register *layout*);
- ``ikseries.sim.cordic_golden.NumpyOps``: the bit-exact integer model (int64 numpy), which
  also checks every register value against its analysed range;
- ``ikseries.hdl.cordic.AmaranthOps``: the RTL; ``ops.stage`` becomes a pipeline register
  (``FoldedAmaranthOps``: each loop, ``ops.loop`` / ``ops.isqrt``, on one set of registers
  instead, an iteration per cycle).

Combinational operations are exact in every back end (numpy int64 is exact because the
analysis proves every intermediate below 2**62; Amaranth widens ``+``, ``*``, shifts
automatically); only pipeline registers have finite widths, taken from the analysis.

Algorithm (units: lengths in mm with ``len_frac`` fractional bits, squared lengths in mm^2
with ``area_frac``, angles in DEGREES with ``angle_frac`` fractional bits, so the theta port
maps to the angle format by a shift and no angle needs a constant multiply):

1. clamp the ports to the workspace; ``R / K_rot`` and ``K_xy * (z_datum + Z)`` by constant
   multiplies (gain compensation done up front, on the narrow inputs);
2. rotation CORDIC of ``(R / K_rot, 0)`` by theta (pre-rotated by 180 deg when
   ``|theta| > 90``): ``R cos(theta)``, ``R sin(theta)``; ``x = D + R cos(theta)``;
3. vectoring CORDIC of ``(x, y)``: ``S1 = atan2(y, x)`` and ``K_xy * hypot(x, y)``;
   ``K_xy * u = K_xy * hypot - K_xy * coxa``; ``K_xy * v`` from step 1;
4. vectoring CORDIC of ``(K_xy u, K_xy v)``: ``atan2(v, u)`` and ``K_xy K_uv d``; one constant
   multiply gives ``d``; ``d^2`` by a multiplier;
5. law of cosines without division: with ``P = d^2 - (f - t)^2`` and ``Q = (f + t)^2 - d^2``,
   ``H = sqrt(P Q)`` (Heron: ``H = 4 * triangle area = sqrt((2fd)^2 - N^2) = sqrt((2ft)^2 - M^2)``)
   by a pipelined restoring integer square root; then two vectoring CORDICs in parallel:
   ``alpha = atan2(H, N)``, ``N = f^2 + d^2 - t^2`` and ``S3 = atan2(H, d^2 - f^2 - t^2)``
   (= 180 - acos((f^2 + t^2 - d^2) / (2ft))); ``S2 = alpha - atan2(v, u)``;
6. pulse scaling ``ticks = round(c1 * angle + c0)`` (constant multiply, add, shift) and the
   clamp to the pulse limits, exactly as the polynomial core's outputs.

Constant multiplies (``ops.mulc``) whose constant has at most :data:`SHIFT_ADD_DIGITS`
canonical signed digits become shift-adds in the RTL (e.g. 480 ticks/degree = 2**9 - 2**5);
the others are ``*`` by a constant, mapped by Yosys (to DSP blocks on all three targets).

Every vectoring CORDIC pre-rotates by +-90 deg when ``x < 0`` so any quadrant converges.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

from ...calibration import LinearMap
from ..plan import PlanInput, bits_for
from ..ports import plan_inputs

__all__ = ["CordicDesign", "CordicPlan", "IntervalOps", "LoopOps", "OperatorOps", "isqrt_stages", "Iv", "datapath", "cordic_gain",
           "DEFAULT_DESIGN", "ITERATION_FIELDS", "WIDTH_FIELDS", "csd", "SHIFT_ADD_DIGITS"]

ITERATION_FIELDS = ("rot_iters", "xy_iters", "uv_iters", "law_iters")
WIDTH_FIELDS = ("len_frac", "area_frac", "angle_frac", "gain_frac", "scale_frac")
MAX_ITERS = 40
MAX_FRAC = 32


@dataclass(frozen=True)
class CordicDesign:
    """Iterations and fixed-point formats of a CORDIC leg solver.

    Parameters
    ----------
    rot_iters : int
        Iterations of the rotation CORDIC (R cos theta, R sin theta).
    xy_iters : int
        Iterations of the vectoring CORDIC atan2(y, x) / hypot(x, y).
    uv_iters : int
        Iterations of the vectoring CORDIC atan2(v, u) / d = hypot(u, v).
    law_iters : int
        Iterations of each of the two law-of-cosines vectoring CORDICs.
    len_frac : int
        Fractional bits of lengths (mm) in the x, y, u, v, d datapath.
    area_frac : int
        Fractional bits of squared lengths (mm^2): d^2, P, Q, N, H.
    angle_frac : int
        Fractional bits of every angle (degrees); at least the theta port's fractional bits.
    gain_frac : int
        Fractional bits of the gain-compensation constants.
    scale_frac : int
        Fractional bits of the ticks-per-degree constant of the pulse scaling.
    """

    rot_iters: int = 18
    xy_iters: int = 18
    uv_iters: int = 18
    law_iters: int = 18
    len_frac: int = 14
    area_frac: int = 6
    angle_frac: int = 14
    gain_frac: int = 18
    scale_frac: int = 4

    def __post_init__(self):
        for name in ITERATION_FIELDS:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= MAX_ITERS:
                raise ValueError(f"{name} must be an integer in 1..{MAX_ITERS}, not {v!r}")
        for name in WIDTH_FIELDS:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= MAX_FRAC:
                raise ValueError(f"{name} must be an integer in 0..{MAX_FRAC}, not {v!r}")

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


#: A generous design (meets the cylinder-leg tolerance with a wide margin); the starting
#: point of ``size_cordic``.
DEFAULT_DESIGN = CordicDesign()


def cordic_gain(n: int) -> float:
    """Gain of ``n`` CORDIC micro-rotations: prod_{i < n} sqrt(1 + 2**(-2 i))."""
    return math.prod(math.sqrt(1.0 + 2.0 ** (-2 * i)) for i in range(n))


def _cordic_bounds(m: float, n: int) -> list[int]:
    """Rigorous bound on |x|, |y| after each of ``n`` truncating micro-rotations of a vector of
    norm <= ``m``: each step scales the norm by sqrt(1 + 4**-i) and its two floor shifts add an
    error vector of norm < sqrt(2)."""
    out, b = [], m
    for i in range(n):
        b = b * math.sqrt(1.0 + 4.0 ** -i) + math.sqrt(2.0)
        out.append(math.ceil(b * (1 + 1e-12)))
    return out


def csd(c: int) -> list[tuple[int, int]]:
    """Canonical signed-digit form of ``c``: [(sign, shift)] with c = sum(sign * 2**shift)
    and no two adjacent non-zero digits (the fewest adders for a shift-add multiply)."""
    out, k = [], 0
    while c:
        if c & 1:
            d = 2 - (c & 3)      # +1 if c = 1 mod 4, -1 if c = 3 mod 4
            out.append((d, k))
            c -= d
        c >>= 1
        k += 1
    return out


#: constant multiplies with at most this many CSD digits are built as shift-adds in the RTL;
#: longer constants are written as ``*`` and left to Yosys (a DSP block where there is one)
SHIFT_ADD_DIGITS = 3


# -- interval analysis back end -------------------------------------------------------------
@dataclass(frozen=True)
class Iv:
    """Integer interval [lo, hi]."""
    lo: int
    hi: int

    @property
    def exact(self) -> int | None:
        return self.lo if self.lo == self.hi else None


_LIMIT = 1 << 62


def _iv(lo: int, hi: int, what: str) -> Iv:
    if max(abs(lo), abs(hi)) >= _LIMIT:
        raise OverflowError(f"CORDIC datapath {what} needs more than 63 bits (interval [{lo}, {hi}]): "
                            f"narrow len_frac / area_frac / gain_frac")
    return Iv(int(lo), int(hi))


class LoopOps:
    """How a back end runs the datapath's loops (CORDIC micro-rotations, square-root steps):
    unrolled, one ``stage`` per iteration (the analysis, the golden model, the pipelined RTL).
    The folded RTL (``ikseries.hdl.cordic.FoldedAmaranthOps``) runs each loop on one set of
    registers instead; its iteration number is then a signal, hence ``table``."""

    def loop(self, tag: str, n: int, step, live: dict, hints=None) -> dict:
        """``n`` iterations ``live = step(ops, live, i)``, stages ``tag0`` .. ``tag{n-1}``;
        ``hints(i)``: the interval hints of iteration ``i`` (analysis only)."""
        for i in range(n):
            live = self.stage(f"{tag}{i}", step(self, live, i), hints(i) if hints else None)
        return live

    def table(self, values, i):
        """``values[i]`` as a constant (``i`` is the iteration number)."""
        return self.c(values[i])

    def isqrt(self, live: dict, xname: str, rname: str, xhi: int, tag: str) -> dict:
        """``live`` with ``xname`` replaced by ``rname`` = floor(sqrt(live[xname])), one result
        bit per stage (see :func:`_isqrt`)."""
        return _isqrt(self, live, xname, rname, xhi, tag)


def isqrt_stages(xhi: int) -> int:
    """Stages of the square root of a value in [0, xhi]: one per result bit."""
    return max(1, (xhi.bit_length() + 1) // 2)


class OperatorOps(LoopOps):
    """The datapath operations that are plain Python operators on the value type (shared by
    the numpy golden model and the Amaranth back end)."""

    def add(self, a, b):
        return a + b

    def sub(self, a, b):
        return a - b

    def neg(self, a):
        return -a

    def mul(self, a, b):
        return a * b

    def shr(self, a, k):
        return a >> k

    def shl(self, a, k):
        return a << k

    def lt(self, a, b):
        return a < b

    def ge(self, a, b):
        return a >= b

    def not_(self, a):
        return ~a


class IntervalOps(LoopOps):
    """Datapath back end over integer intervals: the range of every pipeline register.

    ``layout`` maps each register, keyed ``(stage index, name)``, to its ``(lo, hi)``;
    ``stage`` intersects a value's interval with a rigorous ``hint`` where interval arithmetic
    alone is loose (CORDIC vector norms, square-root remainders).
    """

    analysis = True

    def __init__(self, ports: dict):
        self._ports = ports
        self.layout: list[dict] = []
        self.stage_names: list[str] = []

    def port(self, name):
        lo, hi = self._ports[name]
        return Iv(lo, hi)

    def c(self, v):
        return _iv(v, v, "constant")

    def add(self, a, b):
        return _iv(a.lo + b.lo, a.hi + b.hi, "add")

    def sub(self, a, b):
        return _iv(a.lo - b.hi, a.hi - b.lo, "sub")

    def neg(self, a):
        return Iv(-a.hi, -a.lo)

    def mul(self, a, b):
        if a is b:
            lo = 0 if a.lo <= 0 <= a.hi else min(a.lo ** 2, a.hi ** 2)
            return _iv(lo, max(a.lo ** 2, a.hi ** 2), "square")
        p = [x * y for x in (a.lo, a.hi) for y in (b.lo, b.hi)]
        return _iv(min(p), max(p), "mul")

    def mulc(self, a, c: int):
        """a * c for an integer constant c."""
        return self.mul(a, self.c(c))

    def shr(self, a, k):
        return Iv(a.lo >> k, a.hi >> k)

    def shl(self, a, k):
        return _iv(a.lo << k, a.hi << k, "shl")

    def lt(self, a, b):
        if a.hi < b.lo:
            return Iv(1, 1)
        if a.lo >= b.hi:
            return Iv(0, 0)
        return Iv(0, 1)

    def ge(self, a, b):
        t = self.lt(a, b)
        return Iv(1 - t.hi, 1 - t.lo)

    def not_(self, a):
        return Iv(1 - a.hi, 1 - a.lo)

    def addsub(self, a, b, sub):
        """a - b if sub else a + b."""
        return self.mux(sub, self.sub(a, b), self.add(a, b))

    def or_(self, a, b):
        if a.exact == 1 or b.exact == 1:
            return Iv(1, 1)
        if a.exact == 0 and b.exact == 0:
            return Iv(0, 0)
        return Iv(0, 1)

    def mux(self, c, a, b):
        if c.exact == 1:
            return a
        if c.exact == 0:
            return b
        return Iv(min(a.lo, b.lo), max(a.hi, b.hi))

    def clamp(self, a, lo=None, hi=None):
        l, h = a.lo, a.hi
        if lo is not None:
            l, h = max(l, lo), max(h, lo)
        if hi is not None:
            l, h = min(l, hi), min(h, hi)
        return Iv(l, h)

    def assume(self, a, lo, hi, why):
        """``a`` is known (proved: ``why``) to lie in [lo, hi]. Only the analysis uses this; the
        int64 model checks the value against the range of the register it is stored in."""
        return Iv(max(a.lo, lo), min(a.hi, hi))

    def stage(self, name, vals, hints=None):
        out = {}
        for k, v in vals.items():
            if hints and k in hints:
                lo, hi = hints[k]
                v = Iv(max(v.lo, lo), min(v.hi, hi))
                if v.lo > v.hi:
                    raise AssertionError(f"stage {name}: hint for {k} excludes every value")
            out[k] = v
        self.layout.append({k: (v.lo, v.hi) for k, v in out.items()})
        self.stage_names.append(name)
        return out


# -- the datapath -------------------------------------------------------------------------
def _round_shift(ops, a, k):
    """a * 2**-k rounded half up (k > 0), exact for k <= 0."""
    if k > 0:
        return ops.shr(ops.add(a, ops.c(1 << (k - 1))), k)
    return ops.shl(a, -k) if k < 0 else a


def _norm_bound(x: Iv, y: Iv) -> float:
    ax = max(abs(x.lo), abs(x.hi))
    ay = max(abs(y.lo), abs(y.hi))
    return math.hypot(ax, ay)


def _micro_rotations(ops, live, n, table, cordics, tag, steer, hint):
    """``n`` CORDIC micro-rotations of every ``(x, y, a)`` in ``cordics`` (register names), one
    pipeline stage each (``ops.loop``): with ``s, ns = steer(ops, x, y, a)`` (the step direction
    and its negation), ``x -= y >> i`` where ``s`` (else ``+=``), ``y -= x >> i`` where ``ns``,
    ``a -= t_i`` where ``s``. ``hint(xn, i)`` gives the interval hints of ``(x, y)`` in analysis mode."""
    def step(ops, live, i):
        new = dict(live)
        for xn, yn, an in cordics:
            x, y, a = live[xn], live[yn], live[an]
            s, ns = steer(ops, x, y, a)
            new[xn] = ops.addsub(x, ops.shr(y, i), s)
            new[yn] = ops.addsub(y, ops.shr(x, i), ns)
            new[an] = ops.addsub(a, ops.table(table, i), s)
        return new

    def hints(i):
        out = {}
        for xn, yn, _ in cordics:
            out[xn], out[yn] = hint(xn, i)
        return out
    return ops.loop(tag, n, step, live, hints if ops.analysis else None)


def _rotate(ops, live, n, table, cordics, tag):
    """Rotation CORDICs: drive each angle ``a`` to 0 rotating ``(x, y)`` by it.
    ``cordics`` = [(x, y, a) register names]; one pipeline stage per iteration."""
    bounds = {}
    if ops.analysis:
        bounds = {xn: _cordic_bounds(_norm_bound(live[xn], live[yn]), n) for xn, yn, _ in cordics}

    def steer(ops, x, y, a):
        neg = ops.lt(a, ops.c(0))       # a < 0: rotate clockwise
        return ops.not_(neg), neg

    def hint(xn, i):
        b = bounds[xn][i]
        return (-b, b), (-b, b)
    return _micro_rotations(ops, live, n, table, cordics, tag, steer, hint)


def _vector_prerotate(ops, x, y, deg90):
    """(x, y) -> (x', y', a) with x' >= 0 and atan2(y, x) = a + atan2(y', x'), a in {0, +-90 deg}."""
    xneg, yneg = ops.lt(x, ops.c(0)), ops.lt(y, ops.c(0))
    x2 = ops.mux(xneg, ops.mux(yneg, ops.neg(y), y), x)
    if ops.analysis:
        x2 = ops.assume(x2, 0, max(x.hi, y.hi, -y.lo), "x' = x if x >= 0 else |y|")
    y2 = ops.mux(xneg, ops.mux(yneg, x, ops.neg(x)), y)
    a = ops.mux(xneg, ops.mux(yneg, ops.c(-deg90), ops.c(deg90)), ops.c(0))
    return x2, y2, a


def _vectoring(ops, live, n, table, cordics, tag):
    """Vectoring CORDICs: drive each ``y`` to 0, accumulating the angle in ``a``; ``x`` ends as
    gain * hypot. ``x`` starts >= 0 and never decreases. One pipeline stage per iteration."""
    bounds = {}
    if ops.analysis:
        bounds = {xn: (live[xn].lo, _cordic_bounds(_norm_bound(live[xn], live[yn]), n))
                  for xn, yn, _ in cordics}

    def steer(ops, x, y, a):
        neg = ops.lt(y, ops.c(0))       # y >= 0: rotate clockwise
        return neg, ops.not_(neg)

    def hint(xn, i):
        x0lo, b = bounds[xn][0], bounds[xn][1][i]
        return (max(0, x0lo), b), (-b, b)
    return _micro_rotations(ops, live, n, table, cordics, tag, steer, hint)


def _isqrt(ops, live, xname, rname, xhi, tag):
    """Pipelined restoring square root: ``rname`` = floor(sqrt(live[xname])), one result bit
    per stage, MSB first. After the step for bit b, root = floor(sqrt(X) / 2**b) and
    rem = X - root**2 * 4**b < (2 root + 1) * 4**b."""
    nb = isqrt_stages(xhi)
    rmax = math.isqrt(xhi)
    root, rem = ops.c(0), live[xname]
    live = {k: v for k, v in live.items() if k != xname}
    for b in reversed(range(nb)):
        trial = ops.add(ops.shl(root, 2 * b + 2), ops.c(1 << (2 * b)))
        take = ops.ge(rem, trial)
        rem = ops.mux(take, ops.sub(rem, trial), rem)
        root = ops.mux(take, ops.add(ops.shl(root, 1), ops.c(1)), ops.shl(root, 1))
        rb = rmax >> b
        hints = {rname: (0, rb), "_rem": (0, min(xhi, (2 * rb + 1) * 4 ** b - 1))}
        vals = {**live, rname: root} if b == 0 else {**live, rname: root, "_rem": rem}
        live = ops.stage(f"{tag}{nb - 1 - b}", vals, hints if ops.analysis else None)
        root = live[rname]
        rem = live.get("_rem")
        live = {k: v for k, v in live.items() if k not in (rname, "_rem")}
    return {**live, rname: root}


def datapath(ops, cp: "CordicPlan") -> dict:
    """The CORDIC leg solver over ``ops``; returns {servo: output ticks}. Every ``ops.stage``
    call is one pipeline register stage carrying every live value."""
    d, k = cp.design, cp.k
    A, L, W, G, S = d.angle_frac, d.len_frac, d.area_frac, d.gain_frac, d.scale_frac
    ir, ith, iz = cp.inputs
    # stage: registered, clamped inputs
    live = ops.stage("in", {
        "r": ops.clamp(ops.port(ir.name), ir.lo, ir.hi),
        "th": ops.clamp(ops.port(ith.name), ith.lo, ith.hi),
        "z": ops.clamp(ops.port(iz.name), iz.lo, iz.hi)})
    # stage: gain-compensating constant multiplies; theta to the angle format, |a| <= 90 deg
    th = live["th"]
    th90 = ops.c(90 << ith.frac)
    above, below = ops.lt(th90, th), ops.lt(th, ops.neg(th90))
    a = ops.shl(th, A - ith.frac)
    a = ops.mux(above, ops.sub(a, ops.c(k["deg180"])), ops.mux(below, ops.add(a, ops.c(k["deg180"])), a))
    live = ops.stage("prep", {"rk": ops.mulc(live["r"], k["kr"]), "zk": ops.mulc(live["z"], k["kv"]),
                              "flip": ops.or_(above, below), "a": a})
    # stage: CORDIC start vector (R / K_rot, 0), negated when theta was turned by 180 deg
    rr = _round_shift(ops, live["rk"], G + ir.frac - L)
    live = ops.stage("start", {
        "x": ops.mux(live["flip"], ops.neg(rr), rr), "y": ops.c(0), "a": live["a"],
        "v": ops.add(_round_shift(ops, live["zk"], G + iz.frac - L), ops.c(k["v_off"]))})
    live = _rotate(ops, live, d.rot_iters, k["atan"], [("x", "y", "a")], "rot")
    # stage: x = D + R cos(theta); pre-rotation
    x, y, a = _vector_prerotate(ops, ops.add(live["x"], ops.c(k["D"])), live["y"], k["deg90"])
    live = ops.stage("xy_pre", {"x": x, "y": y, "a": a, "v": live["v"]})
    live = _vectoring(ops, live, d.xy_iters, k["atan"], [("x", "y", "a")], "xy")
    # stage: u = hypot - coxa (all scaled by K_xy); pre-rotation
    u, v, a = _vector_prerotate(ops, ops.sub(live["x"], ops.c(k["u_off"])), live["v"], k["deg90"])
    live = ops.stage("uv_pre", {"s1": live["a"], "x": u, "y": v, "a": a})
    live = _vectoring(ops, live, d.uv_iters, k["atan"], [("x", "y", "a")], "uv")
    s1, auv = live["s1"], live["a"]
    # d: gain compensation, square, area format
    live = ops.stage("d_mul", {"s1": s1, "auv": auv, "dk": ops.mulc(live["x"], k["kd"])})
    live = ops.stage("d", {"s1": live["s1"], "auv": live["auv"], "d": _round_shift(ops, live["dk"], G)})
    dd = live["d"]
    live = ops.stage("d_sq", {"s1": live["s1"], "auv": live["auv"], "sq": ops.mul(dd, dd)})
    live = ops.stage("d2", {"s1": live["s1"], "auv": live["auv"],
                            "d2": _round_shift(ops, live["sq"], 2 * L - W)})
    d2 = live["d2"]
    live = ops.stage("law", {
        "s1": live["s1"], "auv": live["auv"],
        "p": ops.clamp(ops.sub(d2, ops.c(k["fmt2"])), 0, None),
        "q": ops.clamp(ops.sub(ops.c(k["fpt2"]), d2), 0, None),
        "n": ops.add(d2, ops.c(k["f2mt2"])), "e": ops.sub(d2, ops.c(k["f2pt2"]))})
    # P + Q = (f+t)^2 - (f-t)^2 whenever both are positive, so P Q <= ((f+t)^2 - (f-t)^2)^2 / 4
    pq_hi = (k["fpt2"] - k["fmt2"]) ** 2 // 4
    live = ops.stage("pq", {"s1": live["s1"], "auv": live["auv"], "n": live["n"], "e": live["e"],
                            "pq": ops.mul(live["p"], live["q"])},
                     {"pq": (0, pq_hi)} if ops.analysis else None)
    live = ops.isqrt(live, "pq", "h", pq_hi, "sqrt")
    # two vectoring CORDICs in parallel: alpha = atan2(H, N), S3 = atan2(H, d^2 - f^2 - t^2)
    xa, ya, aa = _vector_prerotate(ops, live["n"], live["h"], k["deg90"])
    xe, ye, ae = _vector_prerotate(ops, live["e"], live["h"], k["deg90"])
    live = ops.stage("law_pre", {"s1": live["s1"], "auv": live["auv"], "xa": xa, "ya": ya, "aa": aa,
                                 "xe": xe, "ye": ye, "ae": ae})
    live = _vectoring(ops, live, d.law_iters, k["atan"], [("xa", "ya", "aa"), ("xe", "ye", "ae")], "law")
    angles = {"s1": live["s1"], "s2": ops.sub(live["aa"], live["auv"]), "s3": live["ae"]}
    live = ops.stage("angles", angles)
    # pulse scaling: ticks = round(c1 * angle + c0), then the clamp to the pulse limits
    live = ops.stage("scale", {s: ops.mulc(live[s], k["c1"][j]) for j, s in enumerate(cp.servos)})
    live = ops.stage("round", {s: ops.shr(ops.add(live[s], ops.c(k["c0"][j])), A + S)
                               for j, s in enumerate(cp.servos)})
    return ops.stage("out", {s: ops.clamp(live[s], *cp.limits[s]) for s in cp.servos})


# -- a design bound to a robot --------------------------------------------------------------
class CordicPlan:
    """A :class:`CordicDesign` bound to a robot: constants, register layout and latency.

    Parameters
    ----------
    robot : ikseries.robot.Robot
        A robot with a cylinder-leg geometry.
    design : CordicDesign
    """

    def __init__(self, robot, design: CordicDesign):
        from ...kinematics import CylinderLeg
        if not isinstance(design, CordicDesign):
            raise TypeError(f"design must be a CordicDesign, not {design!r}")
        geometry = getattr(robot, "geometry", None)
        if not isinstance(geometry, CylinderLeg):
            raise TypeError(f"robot must be a Robot with a CylinderLeg geometry, not {robot!r}")
        self.robot, self.design = robot, design
        self.inputs: list[PlanInput] = plan_inputs(robot)
        ith = self.inputs[1]
        if design.angle_frac < ith.frac:
            raise ValueError(f"angle_frac must be >= the {ith.name} input's frac_bits ({ith.frac}), "
                             f"not {design.angle_frac!r}")
        self.servos: tuple[str, ...] = tuple(robot.servos)
        self.limits: dict[str, tuple[int, int]] = robot.pulse_limits_ticks()   # per servo
        self.k = self._constants()
        ia = IntervalOps({i.name: i.port_range for i in self.inputs})
        out = datapath(ia, self)
        self.layout: list[dict] = ia.layout
        self.stage_names: list[str] = ia.stage_names
        self.output_bounds = {s: (v.lo, v.hi) for s, v in out.items()}

    def _constants(self) -> dict:
        d, g, robot = self.design, self.robot.geometry, self.robot
        A, L, W, G, S = d.angle_frac, d.len_frac, d.area_frac, d.gain_frac, d.scale_frac
        k_rot, k_xy, k_uv = (cordic_gain(n) for n in (d.rot_iters, d.xy_iters, d.uv_iters))
        n_table = max(d.rot_iters, d.xy_iters, d.uv_iters, d.law_iters)
        f, t = g.femur, g.tibia
        area = lambda val: round(val * 2 ** W)  # noqa: E731
        cal = g.kinematic_calibration(robot.joint_calibration)   # the datapath's angles are kinematic
        tpp = robot.ticks_per_pu
        c1, c0 = [], []
        for j, m in enumerate(cal.servos):
            if not isinstance(m, LinearMap):
                raise ValueError(f"the CORDIC datapath scales angles to pulses linearly: calibration.servos."
                                 f"{robot.servos[j]}.table needs the polynomial fit")
            per_deg = tpp * m.pu_per_degree          # ticks per degree
            off = tpp * ((m.pulse_pu + m.trim_pu if m.trim_pu else m.pulse_pu) - m.pu_per_degree * m.angle_deg)
            c1.append(round(per_deg * 2 ** S))
            c0.append(round(off * 2 ** (A + S)) + (1 << (A + S - 1) if A + S > 0 else 0))
        return {
            "atan": [round(math.degrees(math.atan(2.0 ** -i)) * 2 ** A) for i in range(n_table)],
            "deg90": 90 << A, "deg180": 180 << A,
            "gains": {"rot": k_rot, "xy": k_xy, "uv": k_uv},
            "kr": round(2 ** G / k_rot),
            "kv": round(k_xy * 2 ** G), "v_off": round(k_xy * g.z_datum * 2 ** L),
            "D": round(g.neutral_distance * 2 ** L), "u_off": round(k_xy * g.coxa * 2 ** L),
            "kd": round(2 ** G / (k_xy * k_uv)),
            "fmt2": area((f - t) ** 2), "fpt2": area((f + t) ** 2),
            "f2mt2": area(f * f - t * t), "f2pt2": area(f * f + t * t),
            "c1": c1, "c0": c0,
        }

    @property
    def latency(self) -> int:
        """Pipeline stages from an input transfer to its output transfer."""
        return len(self.layout)

    def register_bits(self) -> int:
        """Total pipeline register bits (constant registers included; synthesis removes them)."""
        return sum(bits_for(lo, hi)[0] for st in self.layout for lo, hi in st.values())

    @property
    def isqrt_stages(self) -> int:
        """Stages of the square root (one per result bit)."""
        return sum(n.startswith("sqrt") for n in self.stage_names)

    @property
    def longest_loop(self) -> int:
        """Iterations of the longest loop (a CORDIC or the square root)."""
        d = self.design
        return max(d.rot_iters, d.xy_iters, d.uv_iters, d.law_iters, self.isqrt_stages)

    def summary(self) -> dict:
        return {"design": self.design.as_dict(), "latency": self.latency,
                "register_bits": self.register_bits(),
                "gains": self.k["gains"], "isqrt_stages": self.isqrt_stages}
