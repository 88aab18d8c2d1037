"""The command dispatcher's microprogram and its assembler. Pure Python:
:class:`~ikseries.hdl.dispatch.Dispatcher` puts the assembled words in a ROM and executes one per
cycle.

The machine (``hdl/dispatch.py``): a 32-bit field register ``F`` that shifts a byte in at its top
(``F <- F >> 8 | X << 24``), the byte ``X`` picked by ``src`` (a payload byte, ``F``'s low byte,
its sign, an answer source ...); one 8-bit subtract-with-borrow unit ``X - Y - B`` (``Y`` the
immediate or ``F``'s low byte) whose borrow ``B`` chains over the bytes of a comparison, so every
range check and the target saturation is a comparison of ``F``'s bytes with an immediate; a
target register ``TG`` (16 bits per coordinate) that shifts ``Y`` in the same way; counters for the payload
address, the channel and the leg, the leg mask ``LM`` (rotated a leg at a time) and an 8-bit
bit-shift register ``S`` (status flags in, mask bits out). Each instruction names its two
successors (``to`` when its condition holds, ``nxt`` otherwise), so the program is placed in any
order: the three dispatch tables (16 words each, the entry of each command at the index
:func:`command_index` gives its code) take fixed addresses, everything else fills the rest.
An instruction marked ``hold`` is a wait: while its condition holds it stays and its register
effects do not happen (its stream ``valid`` strobes stay up), the cycle it falls through they do.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

from . import protocol as P
from .answers import answer_bytes, scalar_offsets
from .link import CLAMPED_WORD, UPTIME_WORD
from .servo_fields import ChannelField, FailsafeAction

__all__ = ["CONDS", "SOURCES", "STROBES", "OPS", "Ins", "Assembled", "Geometry", "command_index", "program",
           "assemble", "encode", "ROM_DEPTH", "ROM_DEPTHS", "fields"]

#: ROM depths tried in turn: 256 words of up to 80 bits are five iCE40 block RAMs; a program of
#: more (more coordinates, servos, legs than a hexapod's) takes the next
ROM_DEPTHS = (256, 512)
ROM_DEPTH = ROM_DEPTHS[0]
#: branch conditions (index 0 is constant 0: ``never``, inverted ``always``)
CONDS = ("0", "B", "BL", "reqok", "ik_ready", "ik_valid", "wr_ready", "tg_ready", "rd_ready", "st_valid",
         "ans_ready", "window", "LM0", "S0", "leglast", "chlast", "chlow0", "applied")
#: the byte sources of ``X`` (``ZERO`` is the default)
SOURCES = ("ZERO", "IMM", "RD", "F0", "SEXT", "CNT", "S", "FLAG", "CMD", "STB")
#: the strobes, one ROM bit each, decoded by nothing (a 4-bit code of twelve of them took a
#: LUT or two each to decode, more than the ROM's fifth block RAM saves: 80 bits are five)
STROBES = ("ACC", "RDV", "STR", "IKV", "IKR", "HDR", "TGV", "WRV", "MTRD", "IDENT", "NACK", "TAKE", "DISP",
           "COMMIT", "CLRO", "OUTS", "CLI", "MT", "LATCH", "BSET", "FMT")
#: strobes whose effects do not wait for a wait's condition (the dispatcher gates only the others)
_UNHELD = frozenset(STROBES) - {"CLI", "HDR", "TAKE", "RDV", "IKV", "IKR", "TGV", "WRV"}
#: the waits whose effects happen as they end, and what ends them (Dispatcher: ``fire``)
_HELD = {"~ik_valid": lambda s: s.wm == "width", "~tg_ready": lambda s: "TGV" in s.sp,
         "~ik_ready": lambda s: "IKV" in s.sp, "~ans_ready": lambda s: "HDR" in s.sp}
#: the operations of the counters, the leg mask, S and the memory write: one ROM bit each
#: (``<field>_<op>``, at most one a field), decoded by nothing
OPS = {"ra": ("inc", "set", "clear"), "ch": ("inc", "load", "clear"), "lm": ("rot", "mask", "one"),
       "s": ("shift", "load"), "wm": ("ans", "width", "pulse")}
_REASON_BAD = 1 + [n for n, _ in P.NACK_REASONS].index("bad_value")
_C = {c.name: c for c in P.COMMANDS}
#: the word of the answer region (after every answer built there) that holds the move time:
#: written by set_move_time as an answer byte is (its 16 bits ride on F's), read back into F by
#: FMT (the read addressed by the instruction before, MTRD), so it takes no register; MT marks
#: it written (a flag that reset clears: a reset does not clear the memory)
MOVE_TIME_WORD = max(answer_bytes(f) for f in (_C["status"].answer, _C["channel_status"].answer, P.NACK_FIELDS))
_NAMES = {c.code: c.name for c in P.COMMANDS}


def fields(depth: int = ROM_DEPTH) -> tuple:
    """ROM word fields of a ROM of ``depth`` words, low bits first: (name, bits)."""
    a = (depth - 1).bit_length()
    return ((("cond", 5), ("inv", 1), ("to", a), ("nxt", a), ("imm", 8), ("src", 4),
             ("shf", 1), ("alu", 1), ("first", 1), ("ysel", 1), ("bias", 1), ("tg", 1), ("hold", 1))
            + tuple((f"{k}_{op}", 1) for k, ops in OPS.items() for op in ops) + tuple((s, 1) for s in STROBES))


def command_index(code: int) -> int:
    """A command's entry in a 16-word dispatch table: two LUTs of the code's low six bits, which
    :func:`assemble` checks tell every request code apart."""
    low, hi = code & 0xF, code >> 4 & 3
    return low ^ ((~hi >> 1 & 1) << 2 | (hi & 1) << 3)


@dataclass(frozen=True)
class Ins:
    """One instruction; ``sp`` its strobes, ``at`` a fixed address ((table, code) for an entry)."""
    label: str | None = None
    cond: str = "never"
    to: str | None = None
    nxt: str | None = None          # default: the next instruction of the list
    imm: int = 0
    src: str = "ZERO"
    shf: bool = False
    alu: str | None = None          # "first" or "chain"
    ysel: bool = False              # Y = F's low byte (else the immediate)
    bias: bool = False              # flip bit 7 of X and Y: a signed comparison's top byte
    ra: str | None = None
    ch: str | None = None
    tg: bool = False
    lm: str | None = None
    s: str | None = None
    sz: bool = False                # S shifts in 0 (else the status flag bsel names)
    bsel: int = 0                   # 0: moving, 1: enabled
    current: bool = False           # RDV: read the current pulse (else the target)
    wm: str | None = None
    hold: bool = False
    sp: frozenset = field(default_factory=frozenset)
    at: tuple | None = None


@dataclass(frozen=True)
class Geometry:
    """What the program is written for."""
    channels: int
    legs: int
    servos: int
    width_bits: int
    bounds: tuple           # per coordinate (lo, hi)
    identity_bytes: int


def _ins(*args, sp=(), **kw):
    return Ins(*args, sp=frozenset(sp), **kw)


def _field(cmd: str, name: str) -> tuple:
    """(payload offset, bytes, signed) of request field ``name`` of command ``cmd``, from the
    protocol table."""
    return scalar_offsets(_C[cmd])[name]


def _kind(cmd: str, name: str) -> tuple:
    """(bytes, signed) of a request field."""
    return _field(cmd, name)[1:]


def _wait(label, cond, **kw):
    return _ins(label=label, cond="~" + cond, to=label, hold=True, **kw)


def _load(nbytes, signed, k=None, first=None):
    """Prime the payload read and take a field of ``nbytes`` into F, extended to 32 bits; with
    ``k`` every byte is compared with ``k``'s (B: F < k; ``signed``: as two's complement).
    ``first`` (keyword arguments) goes into the priming instruction (a table entry)."""
    out = [_ins(ra="inc", **(first or {}))]
    kb = None if k is None else (k & 0xFFFFFFFF).to_bytes(4, "little")
    for i in range(4):
        alu = {} if kb is None else {"alu": "first" if i == 0 else "chain", "imm": kb[i], "bias": signed and i == 3}
        src = "RD" if i < nbytes else ("SEXT" if signed else "ZERO")
        out.append(_ins(src=src, shf=True, ra="inc" if i < nbytes - 1 else None, **alu))
    return out


def _rotate(k, signed):
    """F compared with ``k`` once more, its bytes rotated through (F unchanged)."""
    kb = (k & 0xFFFFFFFF).to_bytes(4, "little")
    return [_ins(src="F0", shf=True, alu="first" if i == 0 else "chain", imm=kb[i], bias=signed and i == 3)
            for i in range(4)]


def _header(label, length):
    """The answer header, offered until the link takes it (after the previous answer's last
    byte: its CRC), then idle."""
    return _wait(label, "ans_ready", sp={"HDR"}, imm=length, nxt="IDLE")


def _write(fld):
    """Offer a parameter write of F to channel Ch until taken, then acknowledge."""
    return _wait("W" + fld.name, "wr_ready", sp={"WRV"}, imm=int(fld), nxt="ACK")


def _entry(table, name):
    return ("table", table, _C[name].code)


def program(g: Geometry) -> list[Ins]:
    """The whole microprogram."""
    return (_common(g) + _status(g) + _channel_status(g) + _writes(g) + _limits(g) + _masks(g)
            + _moves(g) + _stage(g))


def _common(g):
    idle = [_ins(label="IDLE", cond="~reqok", to="IDLE", hold=True, sp={"TAKE"}, at=("fixed", 0)),
            _ins(sp={"DISP"}, imm=1, nxt=None)]
    ident = [_ins(sp={"ACC", "IDENT"}, nxt="IDHDR", at=_entry(0, "identity")), _header("IDHDR", g.identity_bytes)]
    nack = [_ins(label="NACK", sp={"ACC", "NACK"}, wm="ans", src="CMD"),
            _ins(wm="ans", src="IMM", imm=_REASON_BAD), _header("NACKHDR", 2), _header("ACK", 0)]
    # a channel field first: checked, kept, then the command's own table
    chans = {_kind(c.name, "channel") for c in P.COMMANDS if c.request and c.request[0].name == "channel"}
    assert len(chans) == 1, chans
    chan = _load(*chans.pop(), g.channels)[1:] + [_ins(cond="~B", to="NACK", ch="load", sp={"DISP"}, imm=2)]
    chan_entries = [_ins(ra="inc", nxt="CH1", at=_entry(0, c.name)) for c in P.COMMANDS
                    if c.request and c.request[0].name == "channel"]
    chan[0] = replace(chan[0], label="CH1")
    # a width field (u24 below 2 ** W), then the command's entry of the third table
    # MTRD: the move time's read for set_pulse's FMT (harmless for the other wide commands)
    wide = _load(*_kind("set_pulse", "pulse"), 1 << g.width_bits)[1:] + [
        _ins(cond="~B", to="NACK", sp={"DISP", "MTRD"}, imm=3)]
    wide[0] = replace(wide[0], label="WD1")
    names = {"set_pulse": "pulse", "set_speed": "speed", "set_accel": "accel", "set_home": "pulse"}
    assert {_kind(c, n) for c, n in names.items()} == {_kind("set_pulse", "pulse")}
    wide_entries = [_ins(ra="inc", nxt="WD1", at=_entry(1, n)) for n in names]
    return idle + ident + nack + chan_entries + chan + wide_entries + wide


def _flag_bytes(g):
    """The status masks (C bits of a u32 each), a channel at a time into S: moving while BL is
    0, then enabled (BL := 1)."""
    c = g.channels
    out = [_wait("FL", "rd_ready", sp={"RDV"}), _wait("FLW", "st_valid"),
           _ins(s="shift", sp={"STR"}, ch="inc", cond="chlast", to="FLEND"),
           _ins(cond="~chlow0", to="FL"), _ins(wm="ans", src="S", cond="always", to="FL")]
    pad = (8 - c % 8) % 8
    out += [_ins(s="shift", sz=True, label="FLEND" if i == 0 else None) for i in range(pad)]
    out.append(_ins(wm="ans", src="S", label=None if pad else "FLEND"))
    out += [_ins(wm="ans", src="IMM", imm=0) for _ in range(4 - (c + 7) // 8)]
    # B := 1 (0 - 1 borrows), then BL := B
    return out + [_ins(cond="BL", to="STC"), _ins(alu="first", imm=1),
                  _ins(sp={"LATCH"}, ch="clear", cond="always", to="FL")]


def _status(g):
    """The masks first (the servo controller's reads take a while), then the counters, so that
    they are read shortly before the answer goes out."""
    masks = answer_bytes(_C["status"].answer[:-2])
    out = [_ins(sp={"ACC", "BSET"}, imm=masks, ch="clear", at=_entry(0, "status"))] + _flag_bytes(g)
    # the uptime's two words, the receiver's counters, clamped, all in the link's counter memory
    # (immediate bits 0-3 the word, bit 4 the byte): a word is read the cycle after its address,
    # so each byte's instruction addresses the next word
    up, n = UPTIME_WORD, len(P.RECEIVER_COUNTERS)
    order = [up, up + 1, *range(n), CLAMPED_WORD]
    out += [_ins(label="STC", sp={"BSET"}, imm=0), _ins(imm=order[0])]
    for i, a in enumerate(order):
        out += [_ins(wm="ans", src="CNT", imm=a), _ins(wm="ans", src="CNT", imm=16 | order[(i + 1) % len(order)])]
    out.append(_header("STHDR", 26))
    return out


def _channel_status(g):
    # F still holds the checked channel field (zero-extended): the answer's channel byte is F0
    # read once the last commit has been applied by a pass: the answer shows every earlier move
    # two reads, the target's and the current pulse's (flags from the second), each pulse's
    # bytes low first (each shifts the status a byte down), in the answer's order
    return [_ins(sp={"ACC"}, wm="ans", src="F0", at=_entry(1, "channel_status")), _wait("CSA", "applied"),
            _wait("CSR", "rd_ready", sp={"RDV"}), _wait("CSW", "st_valid"),
            _ins(wm="ans", src="STB"), _ins(wm="ans", src="STB"), _ins(wm="ans", src="STB", sp={"STR"}),
            _wait("CSR2", "rd_ready", sp={"RDV"}, current=True), _wait("CSW2", "st_valid"),
            _ins(wm="ans", src="STB"), _ins(wm="ans", src="STB"), _ins(wm="ans", src="STB"),
            _ins(wm="ans", src="FLAG", bsel=0), _ins(wm="ans", src="FLAG", bsel=1, sp={"STR"}),
            _header("CSHDR", 9)]


def _writes(g):
    w = g.width_bits
    out = []
    for name, fld in (("set_speed", ChannelField.SPEED), ("set_accel", ChannelField.ACCEL),
                      ("set_home", ChannelField.HOME)):
        out += [_ins(sp={"ACC"}, at=_entry(2, name)), _write(fld)]
    # the trim: signed, in [-2 ** W, 2 ** W)
    out += [*_load(*_kind("set_trim", "trim"), -(1 << w), first={"at": _entry(1, "set_trim")}), _ins(cond="B", to="NACK"),
            *_rotate(1 << w, True), _ins(cond="~B", to="NACK"), _ins(sp={"ACC"}), _write(ChannelField.TRIM)]
    out += [*_load(*_kind("set_failsafe_action", "action"), max(FailsafeAction) + 1,
                   first={"at": _entry(1, "set_failsafe_action")}),
            _ins(cond="~B", to="NACK"), _ins(sp={"ACC"}), _write(ChannelField.FAILSAFE)]
    nbytes, signed = _kind("set_failsafe", "periods")
    out += [*_load(nbytes, signed, (1 << w) if w < 8 * nbytes else None, first={"at": _entry(0, "set_failsafe")})]
    if w < 8 * nbytes:
        out.append(_ins(cond="~B", to="NACK"))
    out += [_ins(sp={"ACC"}), _write(ChannelField.TIMEOUT)]
    out += [*_load(*_kind("set_move_time", "periods"),
                   first={"at": _entry(0, "set_move_time"), "sp": {"BSET"}, "imm": MOVE_TIME_WORD}),
            _ins(sp={"ACC", "MT"}, wm="ans", src="F0", nxt="ACK")]
    return out


def _reload(offset, nbytes):
    """F := the unsigned field at payload ``offset`` again."""
    return [_ins(ra="set", imm=offset), *_load(nbytes, False)]


def _limits(g):
    """max (below 2 ** W) into F; min streamed in against it byte by byte (min - max - 1 borrows:
    min <= max), leaving min in F for its write; max loaded again for its own."""
    (lo_at, lo_n, _), (hi_at, hi_n, _) = _field("set_limits", "min"), _field("set_limits", "max")
    assert lo_n == hi_n and not _field("set_limits", "min")[2]
    out = [_ins(ra="set", imm=hi_at, at=_entry(1, "set_limits")), *_load(hi_n, False, 1 << g.width_bits),
           _ins(cond="~B", to="NACK", ra="set", imm=lo_at), _ins(ra="inc")]
    # the chain starts with a borrow (sz on the first byte)
    out += [_ins(src="RD" if i < lo_n else "ZERO", shf=True, ra="inc" if i < lo_n - 1 else None, ysel=True,
                 alu="first" if i == 0 else "chain", sz=i == 0) for i in range(4)]
    # accepted after the last payload read: once accepted, the next frame may take the bank
    out += [_ins(cond="~B", to="NACK"),
            _wait("LMIN", "wr_ready", sp={"WRV"}, imm=int(ChannelField.MIN)),
            *_reload(hi_at, hi_n), _ins(sp={"ACC"}), _write(ChannelField.MAX)]
    return out


def _masks(g):
    """enable / relax: the mask checked, F := 1 / 0 (the value written), then a write per set bit,
    the request accepted after them (the mask's bytes are read as the writes go)."""
    c = g.channels
    k = (1 << c) if c < 32 else None
    out = [_ins(ra="inc", at=_entry(0, name), nxt="MK1") for name in ("enable", "relax")]
    assert _kind("enable", "channels") == _kind("relax", "channels")
    load = _load(*_kind("enable", "channels"), k)[1:]
    load[0] = replace(load[0], label="MK1")
    out += load + [_ins(cond="~B" if k is not None else "never", to="NACK", sp={"DISP"}, imm=3)]
    for name, value in (("enable", 1), ("relax", 0)):
        out += [_ins(ra="clear", ch="clear", src="IMM", imm=value, shf=True, at=_entry(2, name))]
        out += [_ins(src="IMM", imm=0, shf=True) for _ in range(2)]
        out.append(_ins(src="IMM", imm=0, shf=True, cond="always", to="MB"))
    out += [_ins(label="MB", ra="inc"), _ins(s="load"),
            _ins(label="B0", cond="~S0", to="B2"), _wait("B1", "wr_ready", sp={"WRV"}, imm=int(ChannelField.ENABLE)),
            _ins(label="B2", s="shift", ch="inc", cond="chlast", to="MACC"), _ins(cond="~chlow0", to="B0", nxt="MB"),
            # accepted after the last mask byte is read: once accepted, the next frame may take the bank
            _ins(label="MACC", sp={"ACC"}, nxt="ACK")]
    return out


def _coord(k, lo, hi, after, prime_after):
    """Coordinate ``k`` (s16, extended to 32 bits) saturated to [lo, hi] into TG, then ``after``
    (whose payload read each way out primes when ``prime_after``); a saturation sets OUT.
    B := below as it loads, BL keeps it; B := not above over a rotation."""
    n = f"K{k}"
    out = _load(2, True, lo)
    out = out if k == 0 else out[1:]        # the previous coordinate primed the read
    out[0] = replace(out[0], label=n)
    rot = _rotate(hi + 1, True)
    rot[0] = replace(rot[0], sp=frozenset({"LATCH"}))
    rot[3] = replace(rot[3], cond="BL", to=n + "lo")
    ra = "inc" if prime_after else None
    out += rot + [_ins(cond="~B", to=n + "hi"), _ins(src="F0", shf=True, tg=True, ysel=True),
                  _ins(src="F0", shf=True, tg=True, ysel=True, nxt=after, ra=ra)]
    for tag, bound in (("lo", lo), ("hi", hi)):
        b = (bound & 0xFFFF).to_bytes(2, "little")
        out += [_ins(label=n + tag, tg=True, imm=b[0], sp={"OUTS"}), _ins(tg=True, imm=b[1], nxt=after, ra=ra)]
    return out


def _skip(label, servos, then):
    """An unselected leg: its channels passed over, a cycle each."""
    out = [_ins(ch="inc", label=label if j == 0 else None) for j in range(servos)]
    out[-1] = replace(out[-1], cond="always", to=then)
    return out


def _moves(g):
    """The leg field, then each leg of the mask: its coordinates saturated, through the core, its
    widths into the buffer (word ``leg * servos + j``)."""
    out = [*_load(*_kind("move_leg", "leg"), g.legs, first={"at": _entry(0, "move_leg")}),
           _ins(cond="~B", to="NACK", lm="one", ch="clear", nxt="LEG")]
    out += [*_load(*_kind("move_legs", "legs"), 1 << g.legs, first={"at": _entry(0, "move_legs")}),
            _ins(cond="~B", to="NACK"),
            *_rotate(1, False), _ins(cond="B", to="NACK", lm="mask", ch="clear", nxt="LEG")]
    coords = len(g.bounds)
    target = next(f for f in _C["move_legs"].request if f.count == "coords")
    assert P.KINDS[target.kind] == (2, True), target      # TG holds 16 bits per coordinate
    out.append(_ins(label="LEG", cond="~LM0", to="SKIP", sp={"CLRO"}, nxt="K0"))
    for k, (lo, hi) in enumerate(g.bounds):
        last = k + 1 == coords
        out += _coord(k, lo, hi, "OFFER" if last else f"K{k + 1}", not last)
    out.append(_wait("OFFER", "ik_ready", sp={"IKV", "CLI"}))
    for j in range(g.servos):
        # each width taken moves the core's output a servo on (RobotCore rotate_outputs)
        out.append(_wait(f"ST{j}", "ik_valid", wm="width", ch="inc",
                         sp={"IKR"} if j == g.servos - 1 else ()))
    out += [_ins(label="LNEXT", lm="rot", cond="leglast", to="MDONE", nxt="LEG", sp={"MTRD"}),
            *_skip("SKIP", g.servos, "LNEXT"),
            _ins(label="MDONE", sp={"ACC", "FMT"}, ch="clear", nxt="STAGE")]
    return out


def _stage(g):
    """Wait for the staging window; stage the legs' (or set_pulse's one) widths; commit. A
    width is read a cycle before it is offered (the buffer's read port follows the channel);
    the move time is F's (FMT, with the request's acceptance: F is not needed after it), read
    from the memory as the instruction before addressed it (MTRD)."""
    out = [_ins(sp={"ACC", "FMT"}, wm="pulse", src="F0", at=_entry(2, "set_pulse")), _wait("SPW", "window"),
           _wait("SPT", "tg_ready", sp={"TGV"}, nxt="COMMIT")]
    out += [_wait("STAGE", "window"), _ins(label="SL", cond="~LM0", to="SSKIP")]
    for j in range(g.servos):
        out += ([_ins()] if j else []) + [_wait(f"SG{j}", "tg_ready", sp={"TGV"}, ch="inc")]
    out += [_ins(label="SNEXT", lm="rot", cond="leglast", to="COMMIT", nxt="SL"),
            *_skip("SSKIP", g.servos, "SNEXT"),
            _ins(label="COMMIT", sp={"COMMIT"}), _ins(nxt="ACK")]
    return out


@dataclass(frozen=True)
class Assembled:
    """The placed program: ``words[a]`` the instruction at address ``a`` (None: free), its
    successors resolved to addresses."""
    words: list
    labels: dict
    to: list
    nxt: list

    def successors(self, a, code=None):
        """Addresses after ``a`` (a dispatch: the entry of command ``code``)."""
        s = self.words[a]
        if s.sp & {"DISP"}:
            return [b for b, w in enumerate(self.words) if w is not None and w.at and w.at[0] == "table"
                    and w.at[1] == s.imm - 1 and w.at[2] == code]
        out = [] if s.cond == "always" else [self.nxt[a]]
        if s.cond != "never" and self.to[a] != a:       # a wait's self loop is counted once
            out.append(self.to[a])
        return out

    def longest(self, start: str, stops: tuple, code: int | None = None) -> int:
        """Most instructions from label ``start`` to one of labels ``stops`` (not counted), each
        wait once, for a request of command ``code``."""
        ends = {self.labels[s] for s in stops}
        memo, active = {}, set()

        def walk(a):
            if a in ends:
                return 0
            if a in memo:
                return memo[a]
            if a in active:
                raise ValueError(f"loop through address {a} before a stop")
            active.add(a)
            best = 1 + max((walk(b) for b in self.successors(a, code)), default=-10 ** 6)
            active.discard(a)
            memo[a] = best
            return best
        return walk(self.labels[start])


def assemble(prog: list[Ins]) -> Assembled:
    """Place the program in the smallest ROM of :data:`ROM_DEPTHS` it fits (table entries and
    fixed words first), resolve labels and fall-throughs."""
    for depth in ROM_DEPTHS[:-1]:
        if len(prog) <= depth:
            return _assemble(prog, depth)
    return _assemble(prog, ROM_DEPTHS[-1])


def _assemble(prog, depth):
    idx = {c.code: command_index(c.code) for c in P.COMMANDS}
    if len(set(idx.values())) != len(idx) or any(c >> 6 for c in idx):
        raise ValueError(f"command codes must have distinct dispatch indices, not {idx!r}")
    prog, words, addr = list(prog), [None] * depth, {}
    for i, s in enumerate(prog):
        if s.at is not None:
            a = s.at[1] if s.at[0] == "fixed" else 16 * (s.at[1] + 1) + idx[s.at[2]]
            if words[a] is not None:
                raise ValueError(f"address {a} twice: {s!r}")
            words[a], addr[i] = s, a
            if s.at[0] == "table" and s.label is None:
                s = prog[i] = replace(s, label=f"T{s.at[1]}_{_NAMES[s.at[2]]}")
                words[a] = s
    free = (a for a in range(depth) if words[a] is None)
    for i, s in enumerate(prog):
        if i not in addr:
            a = next(free, None)
            if a is None:
                raise ValueError(f"the program must fit {depth} words, not {len(prog)}")
            words[a], addr[i] = s, a
    labels = {}
    for i, s in enumerate(prog):
        if s.label is not None:
            if s.label in labels:
                raise ValueError(f"label {s.label!r} twice")
            labels[s.label] = addr[i]
    to, nxt = [0] * depth, [0] * depth
    for i, s in enumerate(prog):
        a = addr[i]
        for name in (s.to, s.nxt):
            if name is not None and name not in labels:
                raise ValueError(f"instruction {i} {s!r}: unknown label {name!r}")
        if s.cond not in ("never", "always") and s.cond.lstrip("~") not in CONDS:
            raise ValueError(f"instruction {i} {s!r}: unknown condition")
        if s.cond != "never" and s.to is None:
            raise ValueError(f"instruction {i} {s!r} branches nowhere")
        if s.hold and (s.shf or s.alu or s.tg or s.ra or s.lm or s.s or s.sp & _UNHELD):
            raise ValueError(f"instruction {i} {s!r}: a wait may change only the channel, the memory, "
                             "the clamped count and the header")
        if s.hold and (s.ch or s.wm or s.sp & {"CLI", "HDR"}) and not _HELD.get(s.cond, lambda s: False)(s):
            raise ValueError(f"instruction {i} {s!r}: a wait with effects must be one of {sorted(_HELD)}")
        to[a] = labels[s.to] if s.to is not None else 0
        if s.nxt is not None:
            nxt[a] = labels[s.nxt]
        elif s.cond != "always" and not s.sp & {"DISP"}:
            if i + 1 == len(prog):
                raise ValueError(f"the last instruction {s!r} must jump, not fall off the program")
            nxt[a] = addr[i + 1]
    return Assembled(words, labels, to, nxt)


def encode(asm: Assembled) -> list[int]:
    """The ROM words."""
    out = []
    for a, s in enumerate(asm.words):
        if s is None:
            out.append(0)
            continue
        base = s.cond.lstrip("~")
        v = {"cond": 0 if base in ("never", "always") else CONDS.index(base),
             "inv": int(s.cond == "always" or s.cond.startswith("~")), "to": asm.to[a], "nxt": asm.nxt[a],
             "imm": s.imm, "src": SOURCES.index(s.src), "shf": int(s.shf), "alu": int(s.alu is not None),
             "first": int(s.alu == "first"), "ysel": int(s.ysel), "bias": int(s.bias), "tg": int(s.tg),
             "hold": int(s.hold)}
        if "DISP" in s.sp:      # the table's address (16 words from 16 * imm) in nxt, free in a dispatch
            v["nxt"] = s.imm << 4
        # the S input's zero and the first borrow (sz), the flag (bsel): immediate bits 1 and 0
        if s.sz and s.alu == "first" and not s.ysel:
            raise ValueError(f"instruction at {a} {s!r}: a first borrow (sz) needs Y = F (ysel)")
        if s.sz or s.bsel:
            if s.imm & 3 and s.imm & 3 != (s.sz << 1 | s.bsel):
                raise ValueError(f"instruction at {a} {s!r}: sz and bsel take immediate bits 1 and 0")
            v["imm"] = s.imm | s.sz << 1 | s.bsel
        # current (the read's choice of pulse) is the bias bit: a read compares nothing
        if s.current:
            if "RDV" not in s.sp or s.alu is not None or s.bias:
                raise ValueError(f"instruction at {a} {s!r}: current is a choice of a read outside comparisons")
            v["bias"] = 1
        for k, ops in OPS.items():
            if getattr(s, k) not in (None, *ops):
                raise ValueError(f"instruction at {a} {s!r}: {k} must be one of {ops}, not {getattr(s, k)!r}")
            v.update({f"{k}_{op}": int(getattr(s, k) == op) for op in ops})
        v.update({k: int(k in s.sp) for k in STROBES})
        word, off = 0, 0
        for name, bits in fields(len(asm.words)):
            assert 0 <= v[name] < 1 << bits, (name, v[name], s)
            word |= v[name] << off
            off += bits
        out.append(word)
    return out
