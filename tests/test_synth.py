"""Yosys resource counts (ikseries.synth) on a tiny Amaranth design: seconds once Yosys is cached."""
from __future__ import annotations

import pytest
from amaranth import Elaboratable, Module, Signal, signed
from amaranth.back import verilog

from ikseries.constraints.devices import CATEGORIES, FAMILIES
from ikseries.synth import SynthError, categorise, synth_counts


class _Tiny(Elaboratable):
    """A registered signed 16x16 multiplier and a free-running 12-bit counter."""

    def __init__(self):
        self.a = Signal(signed(16))
        self.b = Signal(signed(16))
        self.y = Signal(signed(32))
        self.count = Signal(12)

    def elaborate(self, platform):
        m = Module()
        ra, rb = Signal.like(self.a), Signal.like(self.b)
        m.d.sync += [ra.eq(self.a), rb.eq(self.b), self.y.eq(ra * rb),
                     self.count.eq(self.count + 1)]
        return m


@pytest.fixture(scope="module")
def tiny_verilog(tmp_path_factory):
    t = _Tiny()
    path = tmp_path_factory.mktemp("synth_src") / "tiny.v"
    path.write_text(verilog.convert(t, name="tiny", ports=[t.a, t.b, t.y, t.count], emit_src=False))
    return path


@pytest.fixture(scope="module")
def tiny_result(tiny_verilog, tmp_path_factory):
    # The work directory is under /tmp: this also checks the YoWASP relative-path handling.
    messages = []
    wd = tmp_path_factory.mktemp("synth_work")
    res = synth_counts(tiny_verilog, "tiny", workdir=wd, progress=messages.append, jobs=2)
    return res, messages, wd


# -- categorisation (no Yosys) -------------------------------------------------------------------

@pytest.mark.parametrize("family, cells, expected", [
    ("ice40", {"SB_LUT4": 5, "SB_DFF": 1, "SB_DFFESR": 2, "SB_DFFNE": 3, "SB_CARRY": 4,
               "SB_MAC16": 6, "SB_RAM40_4K": 7, "SB_RAM40_4KNR": 1, "SB_SPRAM256KA": 8,
               "SB_IO": 2, "SB_GB": 1, "$scopeinfo": 99},
     {"LUT": 5, "FF": 6, "carry": 4, "DSP": 6, "BRAM": 8, "SPRAM": 8, "io": 3}),
    ("ecp5", {"LUT4": 10, "PFUMX": 2, "L6MUX21": 1, "TRELLIS_FF": 20, "CCU2C": 3,
              "MULT18X18D": 4, "ALU54B": 1, "DP16KD": 2, "PDPW16KD": 1, "TRELLIS_DPR16X4": 5,
              "TRELLIS_IO": 7},
     {"LUT": 16, "mux": 3, "FF": 20, "carry": 3, "DSP": 5, "BRAM": 3, "LUTRAM": 5, "io": 7}),
    ("xc7", {"LUT1": 1, "LUT2": 2, "LUT3": 3, "LUT4": 4, "LUT5": 5, "LUT6": 6, "INV": 1,
                "FDRE": 10, "FDSE": 1, "FDCE": 2, "FDPE": 3, "CARRY4": 7, "DSP48E1": 2,
                "RAMB18E1": 1, "RAMB36E1": 2, "MUXF7": 3, "MUXF8": 1, "RAM64M": 1,
                "SRLC32E": 2, "IBUF": 4, "OBUF": 5, "BUFG": 1},
     {"LUT": 22, "FF": 16, "carry": 7, "DSP": 2, "BRAM": 3, "mux": 4, "LUTRAM": 3, "io": 10}),
])
def test_categorise_known_cells(family, cells, expected):
    counts, other = categorise(family, cells)
    assert set(counts) == set(CATEGORIES)
    assert counts == {c: expected.get(c, 0) for c in CATEGORIES}
    assert other == {}


def test_ecp5_lut_counts_the_lut4s_of_carry_cells():
    """An ECP5 CCU2C occupies both LUT4s of its slice: LUT counts them, the other families'
    hard carry cells take no LUT."""
    assert categorise("ecp5", {"LUT4": 7, "CCU2C": 4})[0]["LUT"] == 7 + 2 * 4
    assert categorise("ecp5", {"CCU2C": 1})[0]["LUT"] == 2
    assert categorise("ice40", {"SB_LUT4": 7, "SB_CARRY": 4})[0]["LUT"] == 7
    assert categorise("xc7", {"LUT2": 7, "CARRY4": 4})[0]["LUT"] == 7


def test_categorise_unknown_cells_are_other():
    counts, other = categorise("ecp5", {"LUT4": 3, "EHXPLLL": 1, "$scopeinfo": 4})
    assert counts["LUT"] == 3 and counts["other"] == 1
    assert other == {"EHXPLLL": 1}
    # iCE40's LUT is not a Xilinx LUT and vice versa
    assert categorise("xc7", {"SB_LUT4": 1})[0]["other"] == 1
    assert categorise("ice40", {"LUT4": 1})[0]["other"] == 1


# -- real Yosys runs --------------------------------------------------------------------------------

def test_all_targets_run(tiny_result):
    res, messages, wd = tiny_result
    assert list(res) == ["ice40", "ecp5", "xc7"]
    for t, r in res.items():
        assert r["target"] == t and r["device"] == FAMILIES[t].title
        assert (wd / t / "stat.json").is_file() and (wd / t / "yosys.log").is_file()
        assert r["seconds"] > 0
        assert r["yosys_seconds"] is not None and r["yosys_seconds"] > 0
    assert any("iCE40UP5K" in m and "DSP" in m for m in messages)


def test_counts_are_consistent(tiny_result):
    res, _, _ = tiny_result
    for t, r in res.items():
        cells, counts = r["cells"], r["counts"]
        assert "$scopeinfo" not in cells
        assert set(counts) == set(CATEGORIES)
        ripple = FAMILIES[t].ripple_luts * counts["carry"]   # ECP5: CCU2C's LUT4s
        assert sum(cells.values()) == r["num_cells"] == sum(counts.values()) - ripple, t
        assert counts["other"] == sum(r["other_cells"].values()), t
        assert r["other_cells"] == {}, (t, r["other_cells"])  # every cell of this design is known


def test_multiplier_uses_dsp_and_counter_uses_ffs(tiny_result):
    res, _, _ = tiny_result
    for t in ("ice40", "ecp5", "xc7"):
        c = res[t]["counts"]
        assert c["DSP"] >= 1, (t, res[t]["cells"])
        assert c["FF"] >= 12, (t, res[t]["cells"])  # at least the counter
        assert c["carry"] >= 1, (t, res[t]["cells"])  # the counter's adder
        assert c["BRAM"] == 0 and c["LUTRAM"] == 0
    assert res["ice40"]["cells"]["SB_MAC16"] >= 1
    assert res["ecp5"]["cells"]["MULT18X18D"] >= 1
    assert res["xc7"]["cells"]["DSP48E1"] >= 1
    # iCE40 and ECP5 keep every register in the fabric: 16 + 16 + 32 + 12 bits
    assert res["ice40"]["counts"]["FF"] == res["ecp5"]["counts"]["FF"] == 76
    # only synth_xilinx inserts I/O buffers
    assert res["xc7"]["counts"]["io"] > 0 and res["ice40"]["counts"]["io"] == 0


def test_broken_verilog_gives_clear_error(tmp_path):
    bad = tmp_path / "bad.v"
    bad.write_text("module broken(input a, output y);\n  assign y = a +;\nendmodule\n")
    with pytest.raises(SynthError) as ei:
        synth_counts(bad, "broken", targets=("ice40",), workdir=tmp_path / "w")
    msg = str(ei.value)
    assert "'ice40'" in msg and "last lines of the yosys log" in msg
    assert "syntax error" in msg.lower()
    assert ei.value.target == "ice40"


def test_missing_top_gives_clear_error(tiny_verilog, tmp_path):
    with pytest.raises(SynthError, match="not_there"):
        synth_counts(tiny_verilog, "not_there", targets=("ecp5",), workdir=tmp_path)


def test_argument_errors(tiny_verilog, tmp_path):
    with pytest.raises(ValueError, match="unknown synthesis target"):
        synth_counts(tiny_verilog, "tiny", targets=("gowin",))
    with pytest.raises(ValueError, match="identifier"):
        synth_counts(tiny_verilog, "tiny; shell", targets=("ice40",))
    with pytest.raises(FileNotFoundError):
        synth_counts(tmp_path / "nope.v", "tiny")


def test_temporary_workdir_is_removed(tiny_verilog, monkeypatch, tmp_path):
    import tempfile

    from ikseries.wasm_cache import warm_yosys
    from ikseries.synth import yosys_command
    warm_yosys(yosys_command())   # its lock file stays in the real temporary directory
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    res = synth_counts(tiny_verilog, "tiny", targets=("ecp5",))
    assert res["ecp5"]["counts"]["DSP"] >= 1
    assert list(tmp_path.iterdir()) == []
