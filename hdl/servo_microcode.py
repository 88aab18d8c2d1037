"""The servo engine's microprogram (the rules of ``sim/servo_model.py`` as single-ALU steps) and
its assembler. Pure Python: :class:`~ikseries.hdl.servo_engine.ServoEngine` puts the assembled
words in a ROM and executes one per cycle.

The machine: an accumulator ``ACC`` (``A`` bits, signed), a shift register ``Q`` (``W`` bits, for
division), one adder ``R = a + (b ^ inv) + cin`` whose flags ``n`` (``R < 0``) and ``z``
(``R == 0``) steer the branch of the same cycle, and the channel memory: each instruction reads
one word (``D``, issued by its predecessor, which names it in ``rdf`` or ``rdt``) and may write
one word with the ``ACC`` it starts with. A write is seen by reads issued after its cycle, which
the assembler checks (:func:`assemble` refuses a successor reading the word just written).
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["OPS", "BASE_CONDS", "CONDS", "SPECIALS", "Scratch", "Ins", "program", "assemble", "Assembled"]

# op -> (a: 0 zero / 1 ACC / 2 ACC << 1 | Q msb / 3 ~ACC, b: D used, inv/cin mode, ACC written, Q mode)
OPS = {
    "NOP": (1, 0, "add", 0, None), "CLR": (0, 0, "add", 1, None), "LD": (0, 1, "add", 1, None),
    "TST": (0, 1, "add", 0, None), "ADD": (1, 1, "add", 1, None), "SUB": (1, 1, "sub", 1, None),
    "CMP": (1, 1, "sub", 0, None), "INC": (1, 0, "inc", 1, None), "DEC": (1, 0, "dec", 1, None),
    "DADD": (1, 1, "dir", 1, None), "DIV": (2, 1, "div", 1, "shift"), "SHQ": (2, 0, "add", 1, "shift"),
    "QCLR": (0, 0, "add", 1, "load"), "LDH": (0, 1, "add", 1, None), "NEG": (3, 0, "inc", 1, None),
}
# a branch condition is one of 16 base conditions, possibly inverted: name -> (base, inverted)
BASE_CONDS = ("0", "n", "z", "le", "staged", "fs_now", "D0", "D1", "DW", "tflag", "last", "ka",
              "nocount", "go", "rdreq", "0")
CONDS = {"never": (0, 0), "always": (0, 1), "n": (1, 0), "~n": (1, 1), "z": (2, 0), "~z": (2, 1),
         "le": (3, 0), "gt": (3, 1), "nocommit": (4, 1), "~fs_now": (5, 1), "D0": (6, 0),
         "~D0": (6, 1), "D1": (7, 0), "DW": (8, 0), "~tflag": (9, 1), "~last": (10, 1),
         "~ka": (11, 1), "nocount": (12, 0), "go": (13, 0), "~rdreq": (14, 1)}
_D_CONDS = ("nocommit", "D0", "~D0", "D1", "DW")
SPECIALS = ("none", "CH0", "START", "CLRKA", "FIRE", "TCAP", "CLAMPED", "CAPTURE", "LOADNEXT",
            "ACCEPT", "ST_T", "ST_C", "ST_M", "ST_E", "INITNEXT")


class Scratch:
    """Words of the scratch row (row ``channels`` of the memory)."""
    TIMEOUT = 0     # ChannelField.TIMEOUT's low three bits are 0: the host writes it here
    COUNT = 1
    FULL = 2        # constant 2**W - 1 (never written)
    REM = 3         # remaining distance along the motion
    SPD = 4         # effective speed limit (FULL for 0 = unlimited)
    UP = 5
    STEPV = 6
    NM1 = 7         # periods left - 1 of a timed move


@dataclass(frozen=True)
class Ins:
    """One instruction: ``op`` on ``D`` = word ``rd`` ((scratch, word) or None), optional write
    ``st`` of the old ACC, branch ``cond`` -> label ``to``, a ``sp`` special strobe."""
    op: str = "NOP"
    rd: tuple | None = None
    mask: bool = False
    st: tuple | None = None
    cond: str = "never"
    to: str | None = None
    sp: str = "none"
    idle: bool = False
    label: str | None = None


def _c(word):
    return (0, int(word))


def _s(word):
    return (1, int(word))


def program(w: int, home_rom: bool, enabled: bool) -> list[Ins]:
    """The whole microprogram for ``W = w`` (channel words from ``servo_engine.Word``)."""
    return (_init(home_rom, enabled) + _idle_status() + _globals() + _commit() + _failsafe()
            + _move(w))


def _final(label=None, st=True):
    """Store the new current pulse, give it to the PWM bank, next channel or back to idle."""
    from .servo_engine import Word
    return [Ins(st=_c(Word.POS) if st else None, sp="LOADNEXT", cond="~last", to="CH0", label=label),
            Ins(cond="always", to="IDLE0")]


def _init(home_rom, enabled):
    from .servo_engine import Word
    zeros = [Word.MIN, Word.SPEED, Word.ACCEL, Word.FAILSAFE, Word.STAGED_TIME, Word.VEL, Word.STOP,
             Word.ACT_ACCEL]
    body = [Ins("LD", _s(Scratch.FULL), st=_c(Word.TRIM), label="INITCH"),
            Ins("LDH" if home_rom else "CLR", st=_c(Word.MAX)),
            Ins(st=_c(Word.HOME)), Ins(st=_c(Word.TARGET)),
            Ins("CLR", st=_c(Word.POS)), Ins("INC" if enabled else "NOP", st=_c(Word.STAGED)),
            Ins("CLR", st=_c(Word.ENABLE))]
    body += [Ins(st=_c(x)) for x in zeros]
    body.append(Ins(st=_c(Word.TIMED), sp="INITNEXT", cond="~last", to="INITCH"))
    # the first instruction needs no operand: nothing was issued before it
    return [Ins("CLR", sp="CH0", label="INIT")] + body


def _idle_status():
    from .servo_engine import Word
    return [Ins(idle=True, cond="go", to="PASS", label="IDLE0"),
            Ins(idle=True, cond="~rdreq", to="IDLE0", sp="ACCEPT", label="IDLE1"),
            Ins(label="S0"),                    # the accepted channel addresses the reads from here
            Ins("LD", _c(Word.TARGET), sp="ST_T"),
            Ins("CMP", _c(Word.POS), sp="ST_C"),
            Ins("TST", _c(Word.VEL), mask=True, sp="ST_M"),
            Ins(rd=_c(Word.ENABLE), sp="ST_E", cond="always", to="IDLE1")]


def _globals():
    return [Ins("CLR", sp="START", cond="~ka", to="G2", label="PASS"),
            Ins(st=_s(Scratch.COUNT), sp="CLRKA"),
            Ins("LD", _s(Scratch.TIMEOUT), cond="nocount", to="CH0", label="G2"),
            Ins("LD", _s(Scratch.COUNT)), Ins("INC"),
            Ins("CMP", _s(Scratch.TIMEOUT), st=_s(Scratch.COUNT), cond="n", to="CH0"),
            Ins(sp="FIRE")]


def _commit():
    from .servo_engine import Word
    return [Ins("LD", _c(Word.STAGED), mask=True, sp="TCAP", cond="nocommit", to="FS0", label="CH0"),
            Ins("ADD", _c(Word.TRIM), st=_c(Word.STAGED)),     # the flags go with this write
            Ins("CMP", _c(Word.MIN), cond="n", to="LOW"),
            Ins("CMP", _c(Word.MAX), cond="le", to="OK"),
            Ins("LD", _c(Word.MAX), sp="CLAMPED", cond="always", to="OK"),
            Ins("LD", _c(Word.MIN), sp="CLAMPED", label="LOW"),
            Ins("CMP", _c(Word.MAX), cond="le", to="OK"),
            Ins("LD", _c(Word.MAX)),
            Ins("CLR", st=_c(Word.TARGET), cond="~tflag", to="UNTIMED", label="OK"),
            Ins("LD", _c(Word.STAGED_TIME)),
            # FS0 with the move time's write, and the failsafe tests after it (FS1, FS2)
            Ins(st=_c(Word.TIMED), cond="~fs_now", to="MV0", label="UNTIMED"),
            Ins("CLR", _c(Word.FAILSAFE), cond="D1", to="FHOME"),
            Ins(rd=_c(Word.FAILSAFE), cond="~D0", to="FHOLD"),
            Ins(st=_c(Word.ENABLE), cond="always", to="OFF1")]


def _failsafe():
    from .servo_engine import Word
    fs = _c(Word.FAILSAFE)
    return [Ins(cond="~fs_now", to="MV0", label="FS0"),
            Ins("CLR", fs, cond="D1", to="FHOME"),
            Ins(rd=fs, cond="D0", to="FRELAX"),
            # hold: the move that would follow leaves everything where it is
            Ins(st=_c(Word.VEL), label="FHOLD"), Ins("LD", _c(Word.POS), st=_c(Word.TIMED)), Ins(st=_c(Word.TARGET)),
            Ins(rd=_c(Word.ENABLE), cond="D0", to="HOLDEN"),
            Ins("CLR"), *_final(st=False),
            *_final("HOLDEN"),
            Ins(st=_c(Word.ENABLE), cond="always", to="OFF1", label="FRELAX"),
            Ins("LD", _c(Word.HOME), st=_c(Word.TIMED), label="FHOME"),
            Ins(st=_c(Word.TARGET)),
            # as MV0.., without the timed-move test (a home move is untimed)
            Ins(rd=_c(Word.ENABLE), cond="~D0", to="OFF"),
            Ins("LD", _c(Word.POS), cond="~z", to="P0"),
            *_jump()]


def _jump(label=None):
    from .servo_engine import Word
    return [Ins("CLR", label=label), Ins(st=_c(Word.VEL)),
            Ins("LD", _c(Word.TARGET), st=_c(Word.TIMED)), *_final()]


def _move(w):
    from .servo_engine import Word
    return [Ins(rd=_c(Word.ENABLE), cond="D0", to="MV1", label="MV0"),
            Ins("CLR", label="OFF"), Ins(st=_c(Word.VEL), label="OFF1"), Ins(st=_c(Word.TIMED)),
            *_final(st=False),
            Ins("LD", _c(Word.POS), cond="z", to="JUMP", label="MV1"),
            Ins("LD", _c(Word.TIMED), cond="~z", to="TM0"),
            *_rest(w), *_jump("JUMP"), *_moving(), *_timed(w)]


def _limits(prefix):
    """REM := the remaining distance in ACC; SPD := the speed limit in force; ACC := act_accel."""
    from .servo_engine import Word
    return [Ins("LD", _c(Word.SPEED), st=_s(Scratch.REM), cond="~z", to=prefix + "2", label=prefix),
            Ins("LD", _s(Scratch.FULL)),
            Ins("LD", _c(Word.ACT_ACCEL), st=_s(Scratch.SPD), cond="z", to="AZ", label=prefix + "2"),
            Ins("LD", _s(Scratch.REM))]


def _rest(w):
    """From rest (step 0): the direction, then land, else up by ``first``, else no step."""
    from .servo_engine import Word
    vel, tgt, pos, stop = _c(Word.VEL), _c(Word.TARGET), _c(Word.POS), _c(Word.STOP)
    act, rem, spd = _c(Word.ACT_ACCEL), _s(Scratch.REM), _s(Scratch.SPD)
    acc = _c(Word.ACCEL)    # the acceleration in force from rest; ACT_ACCEL := it on the way
    return [Ins("LD", vel, mask=True, cond="~z", to="MOVING", label="P0"),
            Ins("LD", tgt),
            Ins("SUB", pos, sp="CAPTURE", cond="n", to="RDOWN"),
            Ins("LD", _c(Word.SPEED), st=rem, cond="~z", to="RSPD2", label="RSPD"),
            Ins("LD", _s(Scratch.FULL)),
            Ins("LD", acc, st=spd, cond="z", to="AZ", label="RSPD2"),
            Ins("LD", rem, st=act),
            # land (VEL written at once: every other way writes it again)
            Ins("CMP", acc, cond="gt", to="FI0"), Ins("CMP", spd, st=vel, cond="gt", to="FI0"),
            Ins("LD", pos, st=stop, label="LAND"), Ins("DADD", rem), *_final(),
            Ins("NEG", label="RDOWN", cond="always", to="RSPD"),
            # first = SPEED ? (r := SPEED % a) or a : a
            Ins("LD", _c(Word.SPEED), cond="z", to="FA", label="FI0"),
            Ins("QCLR"),
            *[Ins("DIV", acc) for _ in range(w - 1)], Ins("DIV", acc, cond="~n", to="FOK"),
            Ins("ADD", acc, cond="~z", to="FU"), Ins("LD", acc, cond="always", to="FU"),
            Ins(cond="~z", to="FU", label="FOK"),
            Ins("LD", acc, label="FA"),
            Ins("CMP", rem, st=vel, cond="gt", to="ZSTEP", label="FU"),
            Ins("LD", pos, st=stop), Ins("DADD", vel, mask=True), *_final(),
            # acceleration 0: step min(remaining, SPEED), no profile
            Ins("LD", rem, label="AZ"), Ins("CMP", spd, cond="le", to="AZ1"),
            Ins("LD", spd), Ins("CLR", st=_s(Scratch.STEPV), label="AZ1"), Ins("LD", pos, st=vel),
            Ins("DADD", _s(Scratch.STEPV)), *_final()]


def _moving():
    """A step in hand: land, up, hold, down (profile_step's order)."""
    from .servo_engine import Word
    vel, tgt, pos, stop = _c(Word.VEL), _c(Word.TARGET), _c(Word.POS), _c(Word.STOP)
    act, rem, spd, up = _c(Word.ACT_ACCEL), _s(Scratch.REM), _s(Scratch.SPD), _s(Scratch.UP)
    return [
        Ins(rd=vel, sp="CAPTURE", cond="DW", to="MDOWN", label="MOVING"),
        Ins("LD", tgt), Ins("SUB", pos, cond="always", to="MSPD"),
        Ins("LD", pos, label="MDOWN"), Ins("SUB", tgt),
        *_limits("MSPD")[:-1], Ins("LD", rem, cond="n", to="DEC0"),
        Ins("CMP", act, cond="gt", to="NL0"), Ins("CMP", spd, cond="gt", to="NL0"),
        Ins("ADD", act), Ins("CMP", vel, mask=True, cond="n", to="NL0"),
        Ins("LD", rem), Ins(st=vel, cond="always", to="LAND"),
        # a step above the speed limit can neither grow nor hold: down
        Ins("LD", vel, mask=True, label="NL0"), Ins("CMP", spd, cond="gt", to="DEC0"),
        Ins("ADD", act), Ins("CMP", spd, st=up, cond="gt", to="HO0"), Ins("ADD", stop),
        Ins("CMP", rem, cond="gt", to="HO0"),
        Ins(st=stop), Ins("LD", up), Ins("LD", pos, st=vel), Ins("DADD", up), *_final(),
        Ins("LD", stop, label="HO0"), Ins("CMP", rem, cond="gt", to="DEC0"),
        Ins("LD", pos), Ins("DADD", vel, mask=True), *_final(),
        Ins("LD", vel, mask=True, label="DEC0"), Ins("SUB", act, cond="le", to="ZSTEP"),
        Ins("LD", stop, st=up), Ins("SUB", vel, mask=True, cond="~n", to="DE5"),
        Ins("CLR"), Ins("LD", up, st=stop, label="DE5"), Ins("LD", pos, st=vel),
        Ins("DADD", up), *_final(),
        Ins("CLR", label="ZSTEP"), Ins("LD", pos, st=vel), *_final()]


def _timed(w):
    """A step of |target - pos| // periods left toward the target, one period left less."""
    from .servo_engine import Word
    tgt, pos, timed = _c(Word.TARGET), _c(Word.POS), _c(Word.TIMED)
    stepv = _s(Scratch.STEPV)
    return [Ins("DEC", label="TM0"),
            Ins("LD", tgt, st=_s(Scratch.NM1)),
            Ins("SUB", pos, sp="CAPTURE", cond="n", to="TMN"),
            Ins("QCLR", label="TMQ"),
            *[Ins("DIV", timed) for _ in range(w)],
            # the quotient from Q into ACC, one bit per cycle
            Ins("CLR"), *[Ins("SHQ") for _ in range(w)],
            Ins(st=stepv), Ins("LD", _s(Scratch.NM1)), Ins("CLR", st=timed),
            Ins("LD", pos, st=_c(Word.VEL)), Ins("DADD", stepv), *_final(),
            Ins("NEG", label="TMN", cond="always", to="TMQ")]


@dataclass(frozen=True)
class Assembled:
    """The program with resolved branches: per instruction its successors' operands."""
    ins: list
    labels: dict
    rdf: list       # operand issued for the fall-through successor
    rdt: list       # operand issued for the branch target

    def longest(self, start: str, stop) -> int:
        """Most instructions from label ``start`` up to and including one where ``stop(i)``."""
        memo, active = {}, set()

        def walk(i):
            if i in memo:
                return memo[i]
            if i in active:
                raise ValueError(f"loop through instruction {i} before a stop")
            active.add(i)
            best = 1 if stop(i) else 1 + max(walk(j) for j in self.successors(i))
            active.discard(i)
            memo[i] = best
            return best
        return walk(self.labels[start])

    def successors(self, i):
        s, cond = self.ins[i], self.ins[i].cond
        out = [] if cond == "always" else [i + 1]
        if cond != "never":
            out.append(self.labels[s.to])
        return out


def assemble(prog: list[Ins]) -> Assembled:
    """Resolve labels, give every instruction its successors' operands, check write-read hazards."""
    labels = {}
    for i, s in enumerate(prog):
        if s.label is not None:
            if s.label in labels:
                raise ValueError(f"label {s.label!r} twice")
            labels[s.label] = i
    if prog[-1].cond != "always":
        raise ValueError(f"the last instruction {prog[-1]!r} must jump, not fall off the program")
    rdf, rdt = [None] * len(prog), [None] * len(prog)
    a = Assembled(prog, labels, rdf, rdt)
    for i, s in enumerate(prog):
        if s.op not in OPS or s.cond not in CONDS or s.sp not in SPECIALS:
            raise ValueError(f"instruction {i} {s!r}: unknown op, cond or special")
        if (OPS[s.op][1] and s.op != "LDH" or s.cond in _D_CONDS or s.mask) and s.rd is None:
            raise ValueError(f"instruction {i} {s!r} uses D but names no word")
        for j in a.successors(i):
            nxt = prog[j]
            if s.st is not None and nxt.rd == s.st and s.sp not in ("LOADNEXT", "INITNEXT"):
                raise ValueError(f"instruction {j} reads {nxt.rd} that {i} writes in the same cycle")
            if j == i + 1 and s.cond != "always":
                rdf[i] = nxt.rd
            if s.cond != "never" and j == labels[s.to]:
                rdt[i] = nxt.rd
    return a

