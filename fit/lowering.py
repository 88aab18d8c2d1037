"""Servo polynomials -> plan operations: the feature nodes, each servo's Horner/Estrin
lowering, the output rounding and clamp, and the multiplier count the structure search costs."""
from __future__ import annotations

from .horner import estrin, lower_poly
from .plan import Plan, PlanBuilder, PlanOutput
from .structure import FeatureSet, ServoFit, input_norms

__all__ = ["FeatureNodes", "parity_variable", "poly_inputs", "servo_nodes", "build_plan", "trial_plan",
           "output_multipliers", "structure_cost", "structure_multipliers", "MIX_EXTRA_MULTIPLIERS"]

MIX_EXTRA_MULTIPLIERS = 2       # fit.lowering = "mixed": extra multiplications allowed per servo


class FeatureNodes:
    """Feature nodes of every kind on one builder, built on first use."""

    def __init__(self, ctx, b: PlanBuilder, fv: int, mixed: bool = False):
        self.ctx, self.b, self.fv, self.mixed = ctx, b, fv, mixed
        self._kinds: dict = {}

    def __getitem__(self, kind: str) -> list:
        stage = self.ctx.stage
        if "cartesian" not in self._kinds:
            self._kinds["cartesian"] = stage.build(self.b, self.fv, self.fv + 4, self.mixed)
        if kind not in self._kinds:
            if kind == "radial":
                self._kinds[kind] = stage.build_radial(self.b, self.fv)
            else:
                robot = self.ctx.robot
                self._kinds[kind] = [nm.build(self.b, self.b.input_nodes[i.name], self.fv)
                                     for nm, i in zip(input_norms(robot), robot.workspace.inputs)]
        return self._kinds[kind]


def parity_variable(fs: FeatureSet) -> int | None:
    """The variable whose parity the lowering splits (the first even/odd one), or None."""
    return next((j for j, a in enumerate(fs.allowed) if a in ("even", "odd")), None)


def poly_inputs(b: PlanBuilder, fs: FeatureSet, feats: list[int], fv: int) -> tuple[list[int], object]:
    """The variable nodes of a servo polynomial over ``fs`` and its coefficient builder: for a
    piecewise polynomial each cut variable becomes the offset in its cell (exact, widened to the
    features' ``fv`` fractional bits so that its powers keep them) and the coefficients are
    looked up by cell (``b.lut`` of the cut's table address, the table in address order); else
    ``feats`` and None (constants)."""
    if fs.cut is None:
        return feats, None
    address, offsets = fs.cut.address(b, {i.name: i for i in b.inputs}, feats)
    feats = list(feats)
    for c, off in zip(fs.cut.cuts, offsets):
        if c.var is not None:
            feats[c.var] = b.align(off, max(fv, b.frac(off)))
    return feats, lambda v, f: b.lut(address, fs.cut.table(v), f)


def servo_nodes(b: PlanBuilder, fs: FeatureSet, poly: dict, feats: list[int], fv: int, frac: int,
                mixed: bool = False) -> int:
    """Lower one servo polynomial: nested Horner, or with ``mixed`` the Horner/Estrin mix of
    least pipeline depth using at most ``MIX_EXTRA_MULTIPLIERS`` more multiplications
    (:func:`ikseries.fit.horner.lower_poly`). For the first even/odd variable v,
    ``E(..., v**2, ...) + v * O(..., v**2, ...)``. A piecewise polynomial (``fs.cut``) takes
    the offset in the cell for the cut variable and looks its coefficients up by cell."""
    feats, coefficient = poly_inputs(b, fs, feats, fv)
    k = parity_variable(fs)
    if mixed:
        return lower_poly(b, poly, feats, frac, coefficient, parity=k, max_extra_muls=MIX_EXTRA_MULTIPLIERS)
    return estrin(b, poly, feats, frac, coefficient, split=None, parity=k)


def build_plan(ctx, fits: list[ServoFit], fv: int, mixed: bool | None = None, limits: dict | None = None) -> Plan:
    """The plan of ``fits`` with features of ``fv`` fractional bits; ``mixed`` None: as the
    context's lowering says. Each output is clamped to its servo's pulse limits (``limits``:
    servo name -> (lo, hi) ticks; None: the robot's)."""
    mixed = ctx.mixed if mixed is None else mixed
    b = PlanBuilder(list(ctx.inputs), operand_bits=ctx.operand_bits)
    nodes = FeatureNodes(ctx, b, fv, mixed)
    limits = ctx.robot.pulse_limits_ticks() if limits is None else limits
    outs = []
    for sf in fits:
        acc = servo_nodes(b, sf.features, sf.poly, nodes[sf.features.kind], fv, sf.frac, mixed)
        out = b.clamp(b.round(acc, 0), *limits[sf.name])
        outs.append(PlanOutput(sf.name, out, acc, "ticks", ctx.ticks_per_pu))
    return b.build(outs)


def trial_plan(ctx, sf: ServoFit, fv: int, mixed: bool | None = None, limits: dict | None = None) -> Plan:
    """The plan of ``sf`` alone with the same operations and intervals as ``build_plan(ctx,
    [sf], fv, mixed, limits)``, built on a builder of ``ctx.trial_builders`` that holds the
    coordinate stage already (its nodes are the same whatever else the builder holds: equal nodes
    are shared): the servo's own nodes are discarded after (:meth:`PlanBuilder.trial`), so the
    stage is lowered once per fit instead of once per trial."""
    mixed = ctx.mixed if mixed is None else mixed
    if (fv, mixed) not in ctx.trial_builders:
        b = PlanBuilder(list(ctx.inputs), operand_bits=ctx.operand_bits)
        ctx.trial_builders[fv, mixed] = b, FeatureNodes(ctx, b, fv, mixed)
    b, nodes = ctx.trial_builders[fv, mixed]
    feats = nodes[sf.features.kind]           # outside the trial: kept for the next ones
    lo, hi = (ctx.robot.pulse_limits_ticks() if limits is None else limits)[sf.name]
    with b.trial():
        acc = servo_nodes(b, sf.features, sf.poly, feats, fv, sf.frac, mixed)
        return b.build([PlanOutput(sf.name, b.clamp(b.round(acc, 0), lo, hi), acc, "ticks", ctx.ticks_per_pu)])


def output_multipliers(plan: Plan) -> dict:
    """Multipliers each output needs, counting the shared coordinate stage in full."""
    return {o.name: sum(1 for i in plan.cone(o.node) if plan.nodes[i].op == "mul") for o in plan.outputs}


def structure_cost(ctx, fs: FeatureSet, terms: list, servo: str | None = None) -> float:
    """Cost (``ctx.cost_model``) of the evaluation of ``servo`` (its output clamp; None: the
    first servo's) with the coordinate stage for ``terms``, known before fitting: the
    structure alone decides it (kept in ``ctx.structure_costs``)."""
    return _priced(ctx, fs, terms, servo)[0]


def structure_multipliers(ctx, fs: FeatureSet, terms: list, servo: str | None = None) -> int:
    """Multiplications of the same evaluation as :func:`structure_cost` (its trial plan): what
    bounds the search's effort (:data:`ikseries.fit.search.MAX_COST`) whatever the cost model."""
    return _priced(ctx, fs, terms, servo)[1]


def _priced(ctx, fs: FeatureSet, terms: list, servo: str | None) -> tuple[float, int]:
    limits = ctx.robot.pulse_limits_ticks()[servo or ctx.robot.servos[0]]
    key = (fs, tuple(terms), tuple(limits))
    if key not in ctx.structure_costs:
        ctx.structure_costs[key] = _trial_cost(ctx, fs, terms, limits)
    return ctx.structure_costs[key]


def _trial_cost(ctx, fs: FeatureSet, terms: list, limits) -> tuple[float, int]:
    # distinct coefficients: equal ones would share Horner sub-expressions; in cells, signs
    # alternating from cell to cell, so that every bit of a table's entries varies and is stored
    # (ikseries.fit.plan.stored_field), as wide as the same magnitude of either sign takes
    cells = fs.cut.cells if fs.cut else 0
    sf = ServoFit("cost", fs, 0, {e: tuple((-1) ** j * (1.0 + k / 4096) for j in range(cells)) if cells
                                  else 1.0 + k / 4096 for k, e in enumerate(terms)}, 0.0, frac=16)
    plan = trial_plan(ctx, sf, 16, mixed=False, limits={"cost": limits})
    return ctx.cost_model.cost(plan, "cost"), output_multipliers(plan)["cost"]
