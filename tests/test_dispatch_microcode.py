"""The dispatcher's microprogram and assembler (pure Python; the hardware runs in test_controller)."""
import pytest

from ikseries.hdl import protocol as P
from ikseries.hdl.dispatch_microcode import (ROM_DEPTHS, Geometry, Ins, assemble, command_index, encode,
                                             fields, program)

HEXAPOD = Geometry(channels=18, legs=6, servos=3, width_bits=17, bounds=((0, 320), (-360, 360), (-200, 200)),
                   identity_bytes=51)


def test_command_index_tells_every_request_code_apart():
    assert sorted(command_index(c.code) for c in P.COMMANDS) == list(range(16))


@pytest.mark.parametrize("g, depth", [(HEXAPOD, 256), (Geometry(1, 1, 1, 8, ((-5, 5),), 19), 256),
                                      (Geometry(32, 8, 4, 24, ((-32768, 32767),) * 4, 51), 512)])
def test_programs_fit_the_rom_and_encode_deterministically(g, depth):
    asm = assemble(program(g))
    words = encode(asm)
    assert len(words) == depth and sum(w is not None for w in asm.words) <= depth
    assert max(words) < 1 << sum(b for _, b in fields(depth))
    assert encode(assemble(program(g))) == words
    # every entry of the first table is a request code's, at its index
    entries = {w.at[2] for w in asm.words if w is not None and w.at and w.at[:2] == ("table", 0)}
    assert entries == {c.code for c in P.COMMANDS}


def test_assembler_refuses_bad_programs():
    with pytest.raises(ValueError, match=r"^label 'A' twice$"):
        assemble([Ins(label="A"), Ins(label="A", cond="always", to="A")])
    with pytest.raises(ValueError, match=r"unknown label 'B'$"):
        assemble([Ins(label="A", cond="always", to="B")])
    with pytest.raises(ValueError, match=r"must jump, not fall off the program$"):
        assemble([Ins(label="A")])
    top = ROM_DEPTHS[-1]
    with pytest.raises(ValueError, match=rf"^the program must fit {top} words, not {top + 1}$"):
        assemble([Ins(label=f"L{i}") for i in range(top)] + [Ins(label="E", cond="always", to="E")])


def test_longest_paths_of_a_move():
    asm = assemble(program(HEXAPOD))
    code = P.command("move_legs").code
    # the command, its leg mask (loaded, then compared again), into the leg loop
    assert asm.longest("IDLE", ("LEG", "NACK"), code) == 2 + 5 + 1 + 4 + 1
    # three coordinates, each its load, a rotation, two branches and two target bytes at most
    assert asm.longest("K0", ("OFFER",)) == 12 + 2 * 11


@pytest.mark.parametrize("g", [HEXAPOD, Geometry(32, 8, 4, 24, ((-32768, 32767),) * 4, 51)])
def test_no_payload_byte_is_read_after_the_request_is_accepted(g):
    """Once a request is accepted (ACC), the link may hand the next good frame's payload to the
    read port (its bank switches): nothing on any path from an ACC to the idle wait reads the
    payload (``src`` RD, or S loaded from the read data), e.g. set_limits' max read again for its
    write or enable's mask bytes beyond the first."""
    asm = assemble(program(g))
    idle = asm.labels["IDLE"]
    accepts = [a for a, w in enumerate(asm.words) if w is not None and "ACC" in w.sp]
    assert accepts
    for a in accepts:
        seen, todo = set(), [a]
        while todo:
            b = todo.pop()
            if b in seen or b == idle:
                continue
            seen.add(b)
            w = asm.words[b]
            assert w.src != "RD" and w.s != "load", (asm.words[a], w)
            todo += [c for c in asm.successors(b) if c not in seen]
