"""The exported Verilog of every recorded core configuration is byte-identical to its record.

The records (``tests/data/verilog_hashes.json``, written by ``python tests/verilog_hashes.py
--record``) pin the generated hardware across refactorings. By default only the configurations
built from the suite's own cylinder-leg plan run; ``pytest --all-hashes`` fits the rest too.
"""
import pytest

import verilog_hashes as vh


def _params():
    for name in vh.CONFIGS:
        marks = () if name in vh.QUICK else (pytest.mark.all_hashes,)
        yield pytest.param(name, marks=marks, id=name)


@pytest.mark.parametrize("name", list(_params()))
def test_verilog_is_byte_identical_to_its_record(name, plan):
    quick = name in vh.QUICK and vh.CONFIGS[name][0] == "cylinder-leg"
    assert vh.sha256_of(name, plan if quick else None) == vh.recorded()[name]


def test_a_changed_core_changes_its_hash(plan):
    """The check can fail: another interval gives other Verilog."""
    assert vh.sha256_of("modulo8", plan) != vh.recorded()["modulo16"]
