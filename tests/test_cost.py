"""The device cost model (ikseries.fit.cost.DeviceCost): its counts against what the cores
instantiate, its prices, the architectures that offer it and the fit key that names it."""
import dataclasses

import numpy as np
import pytest
from amaranth.back import verilog

from helpers import tiny_grid_plan, tiny_piecewise_plan, tiny_plan
from ikseries.constraints.devices import family, part, primitive
from ikseries.fit.cost import COSTS, DeviceCost, MultiplierCount, Usage
from ikseries.fit.plan import PlanBuilder, PlanInput, PlanOutput, lut_groups, stored_field
from ikseries.hdl.modulo import ModuloEvaluator

ECP5 = "ecp5-25f"


def product_plan(bits: int):
    """y = clamp(a * b) of two unsigned ``bits``-bit ports: one product of two (bits + 1)-bit
    signed operands."""
    inputs = [PlanInput(n, "mm", 0, 0, (1 << bits) - 1, bits, False) for n in "ab"]
    b = PlanBuilder(inputs)
    p = b.mul(b.input_nodes["a"], b.input_nodes["b"])
    return b.build([PlanOutput("y", b.clamp(p, 0, 1000), p, "ticks", 1.0)])


def table_plan(depth: int, tables: int = 2, seed: int = 0, offset: float = 0.0, scale: float = 100.0):
    """y = clamp(t0[a] * b + t1[a] + ...) with ``depth`` cells of port a (one per value) and
    ``tables`` coefficient tables read at one index: one ROM of ``depth`` words, entries
    ``offset + scale * N(0, 1)``."""
    rng = np.random.default_rng(seed)
    bits = (depth - 1).bit_length()
    inputs = [PlanInput("a", "mm", 0, 0, depth - 1, bits, False), PlanInput("b", "deg", 4, -100, 100, 8, True)]
    b = PlanBuilder(inputs)
    cell, _ = b.cell(b.input_nodes["a"], 0)
    luts = [b.lut(cell, tuple(offset + float(v) for v in rng.normal(size=depth) * scale), 4) for _ in range(tables)]
    acc = b.mul(luts[0], b.input_nodes["b"])
    for t in luts[1:]:
        acc = b.add(acc, t)
    out = b.clamp(b.round(acc, 0), -1000, 1000)
    return b.build([PlanOutput("y", out, acc, "ticks", 1.0)])


def instances(plan, name: str, ii: int = 1) -> int:
    """``name`` primitives in the Verilog of the ECP5 modulo core of ``plan`` at interval ``ii``
    (products and registered tables on DSP and block RAM primitives)."""
    core = ModuloEvaluator(plan, ii, dsp=family("ecp5").dsp, dsp_registers="ecp5")
    return verilog.convert(core, name="m", emit_src=False).count(f"{name} #(")


@pytest.mark.parametrize("make", [tiny_plan, tiny_piecewise_plan, lambda: tiny_grid_plan()[0]])
def test_small_plans_count_what_the_modulo_core_instantiates(make):
    """Narrow products: one DSP block each, as many as the modulo core at interval 1 has
    multipliers and MULT18X18D primitives; 4-word tables: LUT ROMs, no DP16KD."""
    plan = make()
    u = DeviceCost(ECP5).usage(plan, "y")
    core = ModuloEvaluator(plan, 1, dsp=family("ecp5").dsp, dsp_registers="ecp5")
    assert u.products == u.dsp == core.multipliers == instances(plan, "MULT18X18D") == plan.count("mul")
    assert u.bram == u.ports == instances(plan, "DP16KD") == 0
    assert u == DeviceCost("ice40-up5k").usage(plan, "y")      # 16 x 16 holds them too
    tables = [(plan.nodes[i].hi + 1, sum(plan.nodes[t].width for t in luts)) for i, luts in lut_groups(plan).items()]
    assert u.lut >= sum(w for _, w in tables)        # a LUT per table bit at least (<= 16 words)


def test_a_wide_product_takes_its_limb_pairs():
    """A 25 x 25-bit product is split into 2 x 2 limbs of the 18 x 18 block: 4 DSP blocks on
    the ECP5 (as the modulo core instantiates them) where a 13 x 13 one takes 1; the iCE40's
    16 x 16 needs 2 x 2 for 25 bits too, 3 x 2 for 33 x 20."""
    wide, narrow = product_plan(24), product_plan(12)
    model = DeviceCost(ECP5)
    assert model.usage(wide, "y").dsp == instances(wide, "MULT18X18D") == 4
    assert model.usage(narrow, "y").dsp == instances(narrow, "MULT18X18D") == 1
    assert MultiplierCount().cost(wide, "y") == MultiplierCount().cost(narrow, "y") == 1
    assert model.cost(wide, "y") > model.cost(narrow, "y") + 3      # 3 blocks more, and their sums' LUTs
    assert DeviceCost("ice40-up5k").usage(wide, "y").dsp == 4
    assert family("ice40").dsp_blocks(33, 20) == 6 and family("ice40").dsp_blocks(16, 16) == 1
    assert family("ecp5").dsp_blocks(25, 18) == family("ecp5").dsp_blocks(18, 25) == 2


@pytest.mark.parametrize("depth,tables", [(128, 1), (256, 2), (1024, 3), (2048, 1)])
def test_deep_tables_take_the_block_rams_the_core_instantiates(depth, tables):
    """A table of at least DP16KD's min_depth words is on DP16KD blocks: the model's count
    equals the blocks the ECP5 modulo core instantiates (its tables side by side); without a
    table primitive (the iCE40) the same table is a LUT ROM."""
    plan = table_plan(depth, tables)
    u = DeviceCost(ECP5).usage(plan, "y")
    assert u.bram == u.ports == instances(plan, "DP16KD") > 0
    ice = DeviceCost("ice40-up5k").usage(plan, "y")
    width = sum(plan.nodes[i].width for i in next(iter(lut_groups(plan).values())))
    assert ice.bram == 0 and ice.lut - u.lut == width * depth // 16
    shallow = table_plan(64, tables)
    assert DeviceCost(ECP5).usage(shallow, "y").bram == instances(shallow, "DP16KD") == 0
    assert depth >= primitive("DP16KD").min_depth > 64


def test_prices_are_device_fractions_in_units_of_one_dsp_block():
    """cost = DSP blocks / interval + the fabric's fraction of the part scaled by its DSP
    count (one block on one product: 1)."""
    plan = table_plan(256, 2)
    for name in ("ecp5-25f", "ice40-up5k"):
        model, cap = DeviceCost(name), part(name).capacities
        u = model.usage(plan, "y")
        fabric = u.lut / cap["LUT"] + u.ff / cap["FF"] + (u.bram / cap["BRAM"] if u.bram else 0)
        assert model.cost(plan, "y") == pytest.approx(u.dsp + cap["DSP"] * fabric)


def test_a_shared_multiplier_is_priced_per_target():
    """At interval ii each multiplier serves ii targets: the DSP share of a product is 1 / ii
    (the modulo core's multipliers: ceil(products / ii)); tables, adders and registers are not
    shared, and the shared multipliers' operand selection costs LUTs."""
    plan = tiny_plan()
    one, four = DeviceCost(ECP5, 1), DeviceCost(ECP5, 4)
    u1, u4 = one.usage(plan, "y"), four.usage(plan, "y")
    assert (u1.dsp, u1.bram, u1.ff) == (u4.dsp, u4.bram, u4.ff) and u4.lut > u1.lut
    cap = part(ECP5).capacities
    assert four.cost(plan, "y") == pytest.approx(u4.dsp / 4 + cap["DSP"] * (u4.lut / cap["LUT"] + u4.ff / cap["FF"]))
    assert four.cost(plan, "y") < one.cost(plan, "y")
    assert ModuloEvaluator(plan, 4, dsp=family("ecp5").dsp).multipliers == -(-u4.dsp // 4)


def test_the_model_is_pure_and_recorded():
    model = DeviceCost(ECP5, 2)
    assert model == DeviceCost(ECP5, 2) and hash(model) == hash(DeviceCost(ECP5, 2)) and model != DeviceCost(ECP5)
    with pytest.raises(dataclasses.FrozenInstanceError):
        model.interval = 3
    assert model.record() == {"cost_model": "device", "part": ECP5, "interval": 2}
    assert COSTS == ("multipliers", "device") and Usage().dsp == 0
    plan = tiny_piecewise_plan()
    assert model.usage(plan, "y") == model.usage(plan, "y")


@pytest.mark.parametrize("make,message", [
    (lambda: DeviceCost("nope"), r"^part must be one of ice40-up5k, ecp5-25f, xc7a35t, not 'nope'$"),
    (lambda: DeviceCost(ECP5, 0), r"^interval must be an integer >= 1, not 0$"),
    (lambda: DeviceCost(ECP5, True), r"^interval must be an integer >= 1, not True$"),
])
def test_bad_parameters_are_refused(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_modulo_and_pipelined_offer_it_with_a_dsp_family():
    from ikseries.hdl.architectures.modulo import Modulo
    from ikseries.hdl.architectures.pipelined import Pipelined
    assert Modulo(4, "ecp5", cost="device").cost_model() == DeviceCost(ECP5, 4)
    assert Pipelined("ice40", cost="device").cost_model() == DeviceCost("ice40-up5k", 1)
    assert Modulo(4, "ecp5").cost_model() == Pipelined().cost_model() == MultiplierCount()
    assert Modulo(4, "ecp5", cost="device").record()["cost"] == "device" and "cost" not in Modulo(4).record()
    with pytest.raises(ValueError, match=r"^cost must be one of multipliers, device, not 'area'$"):
        Modulo(4, "ecp5", cost="area")
    with pytest.raises(ValueError, match=r"^dsp must be one of ice40, ecp5, xc7 with cost 'device' \(the family "
                                         r"whose reference part prices the plan\), not None$"):
        Pipelined(cost="device")


def test_hardware_cost_chooses_the_model_and_joins_the_fit_key(robot):
    from ikseries.architecture import cost_model
    from ikseries.robot import RobotError, fit_record, robot_record, with_hardware
    dev = with_hardware(robot, architecture="modulo", interval=2, dsp="ecp5", cost="device")
    assert cost_model(dev) == DeviceCost(ECP5, 2)
    assert dev.fit_record()["cost_model"] == DeviceCost(ECP5, 2).record()
    assert fit_record(robot_record(dev)) == dev.fit_record()          # from a plan's record too
    assert "cost_model" not in robot.fit_record() and "cost" not in robot_record(robot)["hardware"]
    assert with_hardware(dev, interval=4).fit_record() != dev.fit_record()
    assert with_hardware(dev, cost="multipliers").fit_record() == \
        with_hardware(robot, architecture="modulo", interval=2, dsp="ecp5").fit_record()
    pipe = with_hardware(robot, dsp="ecp5", cost="device")
    assert cost_model(pipe) == DeviceCost(ECP5, 1)
    with pytest.raises(RobotError, match=r"^hardware.architecture must be modulo or pipelined when hardware.cost is "
                                         r"'device' \(the cores that price a plan on the device\), not 'auto'$"):
        with_hardware(robot, architecture="auto", cost="device")
    with pytest.raises(RobotError, match=r"^hardware.dsp must be one of ice40, ecp5, xc7 when hardware.cost is "
                                         r"'device' \(the family whose reference part prices the plan\), not 'none'$"):
        with_hardware(robot, dsp="none", cost="device")
    with pytest.raises(RobotError, match=r"^hardware.cost must be one of multipliers, device, not 'luts'$"):
        with_hardware(robot, cost="luts")


def test_the_fitter_chooses_other_structures_by_the_device(small_robot, small_fitted):
    """Where the multiplier count and the device disagree, the fit follows its model: with
    exact products (some wider than 18 x 18) the ECP5 model's plan takes fewer DSP blocks of
    the part than the multiplier count's (other structures for some servos), and records the
    model it minimised; fitted in worker processes, the same plan."""
    from ikseries.architecture import cost_model
    from ikseries.fit.fitter import fit_robot
    from ikseries.robot import with_hardware
    plan, fits = small_fitted
    robot = with_hardware(small_robot, dsp="ecp5", cost="device")
    model = cost_model(robot)
    dev_plan, dev_fits = fit_robot(robot, cost_model=model)
    assert model == DeviceCost(ECP5) and dev_plan.meta["method"]["cost_model"] == model.record()
    assert "cost_model" not in plan.meta["method"]
    assert [sf.features.structure() for sf in dev_fits] != [sf.features.structure() for sf in fits]
    assert model.usage(dev_plan).dsp < model.usage(plan).dsp
    assert sum(model.cost(dev_plan, o.name) for o in dev_plan.outputs) < \
        sum(model.cost(plan, o.name) for o in plan.outputs)
    # the model goes to the servos' worker processes: the same plan, byte for byte
    assert fit_robot(robot, cost_model=model, jobs=2)[0].dumps() == dev_plan.dumps()


@pytest.mark.parametrize("depth", [65, 96, 127])
def test_a_table_synthesis_may_put_on_an_unregistered_block_ram_cannot_run_one_target_per_clock(depth):
    """On the ECP5 a table deeper than one logic level reads (LUT4s through PFUMX and L6MUX21:
    ``rom_level_words`` = 64) and shallower than DP16KD's ``min_depth`` stays out of the
    modulo core's registered block RAMs, and Yosys builds it as LUTs of several levels or on a
    DP16KD read without its output register (measured: modulo1dt fitted so, 147-150 MHz
    against 217): at interval 1, where the clock is the rate, it is priced infinite; at
    interval 4, and where there is no table primitive (iCE40), as LUTs. Either side of the
    band: priced."""
    ecp5, dp16kd = family("ecp5"), primitive("DP16KD")
    assert ecp5.rom_level_words == 1 << ecp5.wide_lut_inputs == 64 < depth < dp16kd.min_depth
    plan = table_plan(depth)
    u = DeviceCost(ECP5).usage(plan, "y")
    assert u.slow_tables == 1 and u.bram == 0 and instances(plan, "DP16KD") == 0
    assert DeviceCost(ECP5).cost(plan, "y") == float("inf")
    assert DeviceCost(ECP5, 4).usage(plan, "y").slow_tables == 1
    assert 0 < DeviceCost(ECP5, 4).cost(plan, "y") < float("inf")
    assert DeviceCost("ice40-up5k").usage(plan, "y").slow_tables == 0
    assert DeviceCost("ice40-up5k").cost(plan, "y") < float("inf")
    for edge in (ecp5.rom_level_words, dp16kd.min_depth):
        assert DeviceCost(ECP5).usage(table_plan(edge), "y").slow_tables == 0
        assert DeviceCost(ECP5).cost(table_plan(edge), "y") < float("inf")


def test_tables_are_priced_at_the_bits_their_rom_stores():
    """Entries far from 0 share their top bits, which the evaluators wire instead of storing
    (``stored_field``): the model prices the stored bits, the ROM the cores lay out (its
    DP16KD blocks counted as the core instantiates them), not the nodes' widths."""
    near, far = table_plan(1024, 3, scale=100.0), table_plan(1024, 3, offset=50000.0, scale=4.0)
    for plan in (near, far):
        luts = next(iter(lut_groups(plan).values()))
        stored = sum(stored_field(plan, i)[0] for i in luts)
        assert DeviceCost(ECP5).usage(plan, "y").bram == instances(plan, "DP16KD") == -(-stored // 18)
        fabric = DeviceCost("ice40-up5k").usage(plan, "y")
        assert fabric.lut - DeviceCost("ice40-up5k").usage(product_plan(8), "y").lut >= stored * 1024 // 16
    wide = sum(far.nodes[i].width for i in next(iter(lut_groups(far).values())))
    assert -(-wide // 18) > DeviceCost(ECP5).usage(far, "y").bram       # the node widths would take more


class _Values(MultiplierCount):
    """A model that prices coefficient values (only its flag differs from the multiplier count)."""
    prices_values = True


@pytest.mark.parametrize("model,chosen", [(MultiplierCount(), "c"), (_Values(), "b")])
def test_the_search_ranks_structures_by_their_fitted_coefficients(monkeypatch, model, chosen):
    """A model that prices coefficient values ranks the structures found (for the finals) and
    the pruned finalists by their prices with the fitted coefficients
    (:func:`ikseries.fit.formats.fitted_cost`), in their order on a tie; the multiplier count
    keeps the search's cost and builds no fitted plan."""
    import types
    import ikseries.fit.search as search
    calls = []

    def fitted(ctx, sf):
        calls.append(sf.name)
        return {"a": 12.0, "b": 11.5, "c": 11.5}[sf.name]
    monkeypatch.setattr(search, "fitted_cost", fitted)
    ctx = types.SimpleNamespace(cost_model=model)
    sfs = {n: types.SimpleNamespace(name=n, features=types.SimpleNamespace(label=lambda: "f"), poly={})
           for n in "abc"}
    entries = [(10.2, sfs["a"]), (10.4, sfs["b"]), (10.0, sfs["c"])]
    ranked = search._ranked(ctx, entries, lambda msg: None)
    assert [e[1].name for _, e in ranked] == (["c", "a", "b"] if chosen == "c" else ["b", "c", "a"])
    assert ranked[0][1] is next(e for e in entries if e[1].name == chosen)     # the entry itself, its cost kept
    assert calls == ([] if chosen == "c" else ["a", "b", "c"])


def test_fitted_cost_prices_the_fitted_coefficients_in_their_narrowest_formats(small_robot, small_fitted):
    """The fitted price is the model's price of the servo's own plan in the narrowest formats
    that keep its certified rounding within the quantization budget, whatever feature precision
    the servo's last price left as the first to try; with no such format (a budget no rounding
    meets) it is infinite."""
    from ikseries.fit.context import FitContext
    from ikseries.fit.formats import fitted_cost, narrowest_formats
    from ikseries.fit.lowering import trial_plan
    model = DeviceCost(ECP5)
    ctx = FitContext.for_robot(small_robot.fitted, 0.1, model)
    sf = small_fitted[1][1]
    fv, (frac,) = narrowest_formats(ctx, [sf])
    plan = trial_plan(ctx, dataclasses.replace(sf, frac=frac), fv)
    assert fitted_cost(ctx, sf) == model.cost(plan, sf.name) < float("inf")
    assert ctx.format_hints == {sf.name: fv}
    for hint in (fv, fv + 5, fv - 3, 8):    # the last one's, a wider one's, a narrower one's: the same formats
        ctx.format_hints[sf.name] = hint
        assert fitted_cost(ctx, sf) == model.cost(plan, sf.name) and ctx.format_hints[sf.name] == fv
    tight = dataclasses.replace(ctx, budget=dataclasses.replace(ctx.budget, quantization=1e-12))
    assert narrowest_formats(tight, [sf]) is None and fitted_cost(tight, sf) == float("inf")
