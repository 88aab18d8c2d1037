"""Small hand-built plans for exhaustive tests, robot records in the flat layout, and fits
shared by the test run's workers."""
import fcntl
import pickle

import numpy as np

from ikseries.fit.fitter import fit_robot
from ikseries.fit.horner import horner
from ikseries.fit.plan import Plan, PlanBuilder, PlanInput, PlanOutput
from ikseries.sim import golden


def tiny_plan(seed=0, clamp=(-100, 100), degree=4, operand_bits=None) -> Plan:
    """Two small inputs, a random 2-variable polynomial of total ``degree`` (<= 4, at most
    cubic in a and quadratic in b), rounded and clamped: small enough to evaluate exhaustively
    over every port value. ``operand_bits``: the builder's product operand limit."""
    rng = np.random.default_rng(seed)
    inputs = [PlanInput("a", "mm", 2, 0, 12, 4, False), PlanInput("b", "deg", 1, -10, 9, 5, True)]
    b = PlanBuilder(inputs, operand_bits=operand_bits)
    a_n = b.align(b.reinterpret(b.input_nodes["a"], 4), 6)   # a / 4 in [0, 0.75]
    b_n = b.reinterpret(b.input_nodes["b"], 5)               # b / 16 in [-0.31, 0.28]
    poly = {(i, j): float(rng.normal() * 50) for i in range(4) for j in range(3) if i + j <= degree}
    acc = horner(b, poly, [a_n, b_n], 5)
    out = b.clamp(b.round(acc, 0), *clamp)
    return b.build([PlanOutput("y", out, acc, "ticks", 1.0)])


def tiny_piecewise_plan(seed=0, shift=2, degree=3, clamp=(-100, 100), operand_bits=None) -> Plan:
    """``tiny_plan``'s inputs, input a cut into cells of 2**shift port values, a random
    polynomial per cell in the offset inside the cell (centred on [-1, 1)) and b, its
    coefficients looked up by cell (``lut``), rounded and clamped to ``clamp``."""
    rng = np.random.default_rng(seed)
    inputs = [PlanInput("a", "mm", 2, 0, 12, 4, False), PlanInput("b", "deg", 1, -10, 9, 5, True)]
    b = PlanBuilder(inputs, operand_bits=operand_bits)
    cell, off = b.cell(b.input_nodes["a"], shift)
    t = b.add(b.reinterpret(off, shift - 1), b.const(-1.0, shift - 1))
    b_n = b.reinterpret(b.input_nodes["b"], 5)
    cells = b.nodes[cell].hi + 1
    poly = {(i, j): tuple(float(v) for v in rng.normal(size=cells) * 50)
            for i in range(degree + 1) for j in range(3) if i + j <= degree}
    acc = horner(b, poly, [t, b_n], 5, lambda v, f: b.lut(cell, v, f))
    out = b.clamp(b.round(acc, 0), *clamp)
    return b.build([PlanOutput("y", out, acc, "ticks", 1.0)])


def tiny_grid_plan(seed=0, shifts=(2, 2), degree=2, clamp=(-100, 100)) -> tuple:
    """``tiny_plan``'s inputs cut into a grid (:class:`~ikseries.fit.features.CutGrid`): a into
    cells of 2**shifts[0] port values, the signed b into cells of 2**shifts[1] (from its lowest
    value); a random polynomial per cell in both offsets (each on [-1, 1)), its coefficients
    looked up by the grid's table address, rounded and clamped. Returns the plan and the
    polynomial (exponents -> coefficient per cell, in cell order)."""
    from ikseries.fit.features import Cut, CutGrid
    rng = np.random.default_rng(seed)
    inputs = [PlanInput("a", "mm", 2, 0, 12, 4, False), PlanInput("b", "deg", 1, -10, 9, 5, True)]
    b = PlanBuilder(inputs)
    grid = CutGrid(*(Cut(k, i.name, s, ((i.hi - i.lo) >> s) + 1) for k, (i, s) in enumerate(zip(inputs, shifts))))
    address, offsets = grid.address(b, {i.name: i for i in inputs})
    poly = {(i, j): tuple(float(v) for v in rng.normal(size=grid.cells) * 50)
            for i in range(degree + 1) for j in range(degree + 1) if i + j <= degree}
    acc = horner(b, poly, offsets, 5, lambda v, f: b.lut(address, grid.table(v), f))
    out = b.clamp(b.round(acc, 0), *clamp)
    return b.build([PlanOutput("y", out, acc, "ticks", 1.0)]), grid, poly


def grid_reference(grid, poly, ports) -> np.ndarray:
    """The float value of :func:`tiny_grid_plan`'s polynomial at port values ``ports`` (clamped
    to the input ranges as the plan's inputs are): cell and offsets computed directly."""
    cells, offs = [], []
    for c, (lo, hi) in zip(grid.cuts, ((0, 12), (-10, 9))):
        u = np.clip(ports[c.port], lo, hi) - lo
        cells.append(u >> c.shift)
        half = 2 ** (c.shift - 1)
        offs.append(((u & (2 ** c.shift - 1)) - half) / half)
    cell = cells[0] * grid.b.cells + cells[1]
    return sum(np.asarray(c)[cell] * offs[0] ** i * offs[1] ** j for (i, j), c in poly.items())


def signed_cell_plan() -> Plan:
    """Cells of the signed input b: ``index`` and ``mask`` of negative values (outputs too),
    a lut indexed by a computed cell number, and a lut whose index never takes its first
    entries (which do not fit the node's width)."""
    b = PlanBuilder([PlanInput("a", "mm", 0, 0, 12, 4, False), PlanInput("b", "deg", 1, -10, 9, 5, True)])
    cell, off = b.cell(b.input_nodes["b"], 2)                  # [-3, 2], [0, 3] (frac 1)
    c0 = b.add(cell, b.const(3, 0))                            # [0, 5]
    c1 = b.add(cell, b.const(4, 0))                            # [1, 6]
    t0 = b.lut(c0, [-7.5, 3.25, 0.5, -1.0, 6.75, -8.0], 2)
    t1 = b.lut(c1, [900.0, -3.0, 5.0, 1.0, -2.0, 7.0, 4.0, -6.0], 0)
    y = b.add(b.mul(t0, off), b.mul(t1, b.input_nodes["a"]))
    outs = [("y", y), ("cell", cell), ("off", off)]
    return b.build([PlanOutput(n, v, v, "ticks", 1.0) for n, v in outs])


def all_ports(plan):
    ranges = []
    for i in plan.inputs:
        lo, hi = i.port_range
        ranges.append(np.arange(lo, hi + 1))
    grid = np.meshgrid(*ranges, indexing="ij")
    return {i.name: g.ravel() for i, g in zip(plan.inputs, grid)}




TINY_INPUTS = [PlanInput("a", "mm", 2, 0, 12, 4, False), PlanInput("b", "deg", 1, -10, 9, 5, True),
               PlanInput("c", "mm", 0, -4, 3, 3, True)]


def tiny_vars(b: PlanBuilder, nvars: int) -> list[int]:
    """Normalised variables of ``TINY_INPUTS``: a / 16 in [0, 0.75], b / 32 in [-0.31, 0.28],
    c / 4 in [-1, 0.75]."""
    make = [lambda: b.align(b.reinterpret(b.input_nodes["a"], 4), 6),
            lambda: b.reinterpret(b.input_nodes["b"], 5),
            lambda: b.align(b.reinterpret(b.input_nodes["c"], 2), 6)]
    return [m() for m in make[:nvars]]


def tiny_ideal_vars(ports: dict, nvars: int) -> list:
    """The real values of ``tiny_vars`` for port integers."""
    make = [lambda: np.clip(ports["a"], 0, 12) / 16, lambda: np.clip(ports["b"], -10, 9) / 32,
            lambda: ports["c"] / 4]
    return [m() for m in make[:nvars]]


def tiny_lowered_plan(lower, nvars: int = 2) -> Plan:
    """``lower(b, var_nodes)`` (the accumulator node, frac 5) on ``nvars`` of ``TINY_INPUTS``,
    rounded and clamped."""
    b = PlanBuilder(TINY_INPUTS[:nvars])
    acc = lower(b, tiny_vars(b, nvars))
    out = b.clamp(b.round(acc, 0), -100, 100)
    return b.build([PlanOutput("y", out, acc, "ticks", 1.0)])


def check_exhaustively(plan, want=None):
    """For every port value: every node in its interval, every node the first output's
    pre-rounding value needs within its rounding bound, and (if ``want(ports)`` is given)
    that value's ideal equal to ``want``."""
    ports = all_ports(plan)
    iv, fv = golden.evaluate(plan, ports), golden.evaluate_ideal(plan, ports)
    bound = plan.rounding_bounds()
    for k, n in enumerate(plan.nodes):
        v = np.asarray(iv[k])
        assert v.min() >= n.lo and v.max() <= n.hi, (k, n.op)
    for k in plan.cone(plan.outputs[0].preround):
        err = np.abs(np.asarray(iv[k]) * 2.0 ** -plan.nodes[k].frac - fv[k])
        assert err.max() <= bound[k] * (1 + 1e-12) + 1e-12, (k, plan.nodes[k].op)
    if want is not None:
        assert np.allclose(fv[plan.outputs[0].preround], want(ports), rtol=0, atol=1e-9)


def simulate_bit_exact(core, plan, targets, **kw):
    """Stream ``targets`` through ``core`` in the Amaranth simulator (``simulate_leg``, keyword
    options passed on) and assert every output equals the golden model; returns the result."""
    from ikseries.sim import golden
    from ikseries.sim.amaranth_sim import simulate_leg
    res = simulate_leg(core, targets, **kw)
    exp = golden.outputs(plan, targets)
    for s in exp:
        assert np.array_equal(res.outputs[s], exp[s]), s
    return res


def flat_record(record: dict) -> dict:
    """A :func:`ikseries.robot.robot_record` in the flat layout that plans were written with
    before the description had parts: every field at the top level, the workspace as
    ``inputs``."""
    flat = {k: record[k] for k in ("name", "description", "legs", "geometry")}
    flat["inputs"] = record["workspace"]["inputs"]
    for part in ("calibration", "fit", "hardware"):
        flat.update(record[part])
    return flat


def shared_fit(tmp_path_factory, name: str, robot):
    """``fit_robot(robot)``, computed by the first worker that asks and read by the others
    (under a lock, so a worker asking while another fits waits for that fit); a fresh copy
    each call, so a caller may change its plan's meta."""
    root = tmp_path_factory.getbasetemp()
    if root.name.startswith("popen-gw"):     # an xdist worker's directory: share its parent
        root = root.parent
    path = root / f"fit-{name}.pickle"
    with open(root / f"fit-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not path.exists():
            path.write_bytes(pickle.dumps(fit_robot(robot)))
        return pickle.loads(path.read_bytes())


def toy_robot(geometry, tolerance=0.5):
    """A robot of ``geometry`` (inputs a, b; one servo y, its angle formula over a math
    namespace) with an identity calibration (pulse = angle), for the certifier's tests."""
    from types import SimpleNamespace

    from ikseries.calibration import Calibration
    return SimpleNamespace(
        geometry=geometry, servos=("y",), fit=SimpleNamespace(tolerance_pu=tolerance),
        workspace=SimpleNamespace(inputs=(SimpleNamespace(name="a"), SimpleNamespace(name="b"))),
        joint_calibration=Calibration.linear(neutral_angles=(0.0,), directions=(1,), neutral_pulse_pu=0.0,
                                             pu_per_degree=1.0))
