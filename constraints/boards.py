"""Board facts: the boards a controller can be flashed to, and the project's own board files.

A :class:`Board` names its FPGA (family of :mod:`~ikseries.constraints.devices`, the vendor
device, package), the oscillator pin and frequency, the UART pins, a status LED, the pins
servos may use in their default order and the ``openFPGALoader -b`` name of its programmer.

Boards of ``amaranth-boards`` (``BOARDS``: registry name -> Board, read on first use;
:data:`BOARD_NAMES` their names) take every pin and the oscillator frequency from
their platform class (:func:`board_from_platform`); only the choice of resources, the servo
pins' order and the programmer are written here. Servo pins of such boards are named as
Amaranth names connector pins, ``<connector>_<number>:<pin>`` (``pmod_0:1`` is pin 1 of the
iCEBreaker's PMOD1A); the package pin behind each is in :attr:`Board.servo_pins`.

Boards that package lacks are described in a TOML file (:func:`load_board_file`), flat keys::

    name = "my-board"            # letters, digits and '-'
    family = "ice40"             # ice40 | ecp5
    device = "iCE40UP5K"         # as Amaranth names it (ECP5: "LFE5U-25F", ...)
    package = "SG48"             # as Amaranth names it (ECP5: "BG381", ...)
    speed = "6"                  # ECP5 only: 6, 7 or 8
    io_standard = "SB_LVCMOS"    # of every pin (ECP5: LVCMOS33, LVCMOS25, ...)
    programmer = "ice40_generic" # openFPGALoader -b name
    clock_pin = "35"
    clock_hz = 12_000_000
    uart_rx = "6"                # the FPGA's receive pin (data from the host)
    uart_tx = "9"
    led_pin = "37"
    led_active_low = true        # optional, default false
    servo_pins = ["4", "2", "47", "45"]   # package pins, in channel order

Servo pins of a board file are its package pins.
"""
from __future__ import annotations

import importlib
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from .devices import PARTS, lookup

__all__ = ["Board", "BoardError", "BOARD_NAMES", "BOARD_FILE_KEYS", "IO_STANDARDS", "IO_ATTRIBUTE", "BITSTREAM_SUFFIX",
           "board", "board_file_text", "board_from_platform", "load_board_file", "parse_board"]

#: single-ended I/O standards a board file may give, per family (the first is the default of
#: amaranth-boards' boards of that family)
IO_STANDARDS = {"ice40": ("SB_LVCMOS",),
                "ecp5": ("LVCMOS33", "LVCMOS25", "LVCMOS18", "LVCMOS15", "LVCMOS12")}
#: the Amaranth resource attribute carrying the I/O standard, per family
IO_ATTRIBUTE = {"ice40": "IO_STANDARD", "ecp5": "IO_TYPE"}
#: the file the family's bitstream packer writes (and openFPGALoader loads)
BITSTREAM_SUFFIX = {"ice40": ".bin", "ecp5": ".bit"}
#: ECP5 speed grades
ECP5_SPEEDS = ("6", "7", "8")
# the Amaranth vendor platform of each family (the registry's family names as keys)
_VENDOR_PLATFORM = {"ice40": "SiliconBluePlatform", "ecp5": "LatticePlatform"}


class BoardError(ValueError):
    """A board name or board file that cannot be used (one line naming the bad value)."""


@dataclass(frozen=True)
class Board:
    """One board: its FPGA, clock, UART, LED, servo pins and programmer.

    Parameters
    ----------
    name : str
        Registry name (or the board file's ``name``).
    family : str
        FPGA family, a name of :data:`ikseries.constraints.devices.FAMILIES` (``ice40``, ``ecp5``).
    device, package : str
        Vendor device and package as Amaranth's platforms name them (``iCE40UP5K``, ``SG48``).
    speed : str
        ECP5 speed grade ("" on the iCE40).
    clock_pin : str
        Package pin of the oscillator.
    clock_hz : int
        The oscillator's frequency.
    uart_rx, uart_tx : str
        Package pins of the UART: ``uart_rx`` receives from the host.
    led : str
        Package pin of the status LED.
    led_active_low : bool
        The LED lights when its pin is low.
    servo_pins : tuple of (str, str)
        (name, package pin) of every pin servos may use, in the default channel order.
    io_standard : str
        I/O standard of the servo pins (and of every pin of a board file).
    programmer : str
        ``openFPGALoader -b`` name of the board.
    platform : str
        ``module:Class`` of its amaranth-boards platform; "" for a board file.
    resources : tuple of (str, str, int)
        (role, Amaranth resource name, number) of the clock, UART and LED in that platform.
    source : str
        Where the facts come from (the platform class or the board file's path).
    """
    name: str
    family: str
    device: str
    package: str
    speed: str
    clock_pin: str
    clock_hz: int
    uart_rx: str
    uart_tx: str
    led: str
    led_active_low: bool
    servo_pins: tuple[tuple[str, str], ...]
    io_standard: str
    programmer: str
    platform: str = ""
    resources: tuple[tuple[str, str, int], ...] = (("clock", "clk", 0), ("uart", "uart", 0), ("led", "led", 0))
    source: str = ""

    @property
    def part(self) -> str | None:
        """The :data:`~ikseries.constraints.devices.PARTS` name of its device (capacities,
        fit device), None when the registry does not list it."""
        return next((p.name for p in PARTS.values() if p.family == self.family and p.part == self.device), None)

    @property
    def servo_pin_names(self) -> tuple[str, ...]:
        return tuple(n for n, _ in self.servo_pins)

    @property
    def bitstream_suffix(self) -> str:
        return BITSTREAM_SUFFIX[self.family]

    def resource(self, role: str) -> tuple[str, int]:
        """(Amaranth resource name, number) of ``role`` ("clock", "uart" or "led")."""
        return next((n, k) for r, n, k in self.resources if r == role)

    def package_pin(self, servo_pin: str) -> str:
        """The package pin of servo pin ``servo_pin``; BoardError naming the board's pins if absent."""
        for n, p in self.servo_pins:
            if n == servo_pin:
                return p
        raise BoardError(f"servo pin must be one of {self.name}'s {', '.join(self.servo_pin_names)}, "
                         f"not {servo_pin!r}")


# -- boards of amaranth-boards ---------------------------------------------------------------------

def _platform_class(path: str):
    module, _, cls = path.partition(":")
    return getattr(importlib.import_module(module), cls)


def _find(resources, name: str, number: int):
    return next(r for r in resources if r.name == name and r.number == number)


def _pins(res, sub: str | None = None):
    """The Pins of resource ``res`` (or of its subsignal ``sub``)."""
    ios = res.ios if sub is None else next(s for s in res.ios if getattr(s, "name", None) == sub).ios
    return ios[0]


def _connector_pin(connectors, ref: str) -> str:
    """The package pin of connector pin ``<name>_<number>:<pin>``."""
    m = re.fullmatch(r"(\w+)_(\d+):(\S+)", ref)
    conn = next(c for c in connectors if (c.name, str(c.number)) == (m[1], m[2]))
    return conn.mapping[m[3]]


def board_from_platform(name: str, platform: str, *, clock: str, uart: str, led: str,
                        servo_pins: tuple[str, ...], programmer: str) -> Board:
    """A :class:`Board` whose pins, device and oscillator are read from the amaranth-boards
    platform class ``platform`` ("module:Class"); ``clock``, ``uart`` and ``led`` are its
    resources ("name" or "name:number"), ``servo_pins`` connector pins in channel order."""
    cls = _platform_class(platform)
    family = next(f for f, base in _VENDOR_PLATFORM.items() if any(b.__name__ == base for b in cls.__mro__))
    refs = {}
    for role, ref in (("clock", clock), ("uart", uart), ("led", led)):
        rname, _, num = ref.partition(":")
        refs[role] = (rname, int(num or 0))
    clk = _find(cls.resources, *refs["clock"])
    uart_res = _find(cls.resources, *refs["uart"])
    led_pins = _pins(_find(cls.resources, *refs["led"]))
    return Board(
        name=name, family=family, device=cls.device, package=cls.package, speed=str(getattr(cls, "speed", "")),
        clock_pin=_pins(clk).names[0], clock_hz=int(clk.clock.frequency),
        uart_rx=_pins(uart_res, "rx").names[0], uart_tx=_pins(uart_res, "tx").names[0],
        led=led_pins.names[0], led_active_low=bool(led_pins.invert),
        servo_pins=tuple((p, _connector_pin(cls.connectors, p)) for p in servo_pins),
        io_standard=IO_STANDARDS[family][0], programmer=programmer, platform=platform,
        resources=tuple((role, *refs[role]) for role in ("clock", "uart", "led")),
        source=f"amaranth-boards {cls.__name__}")


def _pmod(number: int) -> tuple[str, ...]:
    return tuple(f"pmod_{number}:{p}" for p in (1, 2, 3, 4, 7, 8, 9, 10))


# PMOD1A and PMOD1B first: PMOD2 carries the break-off LED and button board while it is attached
_ICEBREAKER_SERVOS = _pmod(0) + _pmod(1) + _pmod(2)
# the header's GP0..GP27, then GN0..GN27 (one row of the ULX3S's two-row headers first)
_ULX3S_SERVOS = tuple(f"gpio_0:{k}+" for k in range(28)) + tuple(f"gpio_0:{k}-" for k in range(28))


# The iCEBreaker's green user LED (a blinking red one reads as an error); the ULX3S's LED 0. openFPGALoader has no "icebreaker": the board's FT2232H
# programmer is its generic iCE40 one.
_SPECS = {
    "icebreaker": dict(platform="amaranth_boards.icebreaker:ICEBreakerPlatform", clock="clk12", uart="uart",
                       led="led_g", servo_pins=_ICEBREAKER_SERVOS, programmer="ice40_generic"),
    "ulx3s-25f": dict(platform="amaranth_boards.ulx3s:ULX3S_25F_Platform", clock="clk25", uart="uart", led="led",
                      servo_pins=_ULX3S_SERVOS, programmer="ulx3s"),
    "ulx3s-85f": dict(platform="amaranth_boards.ulx3s:ULX3S_85F_Platform", clock="clk25", uart="uart", led="led",
                      servo_pins=_ULX3S_SERVOS, programmer="ulx3s"),
}

#: the registry's board names, in order (known without importing amaranth-boards)
BOARD_NAMES = tuple(_SPECS)
_boards: dict[str, Board] = {}


def __getattr__(name):
    # BOARDS (registry name -> Board) reads the amaranth-boards platforms on first use only, so
    # that importing this module (e.g. for the command line's help) stays cheap
    if name == "BOARDS":
        if not _boards:
            _boards.update((n, board_from_platform(n, **spec)) for n, spec in _SPECS.items())
        return _boards
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def board(name_or_file) -> Board:
    """The registry board called ``name_or_file``, or the board file at that path (``.toml``)."""
    if isinstance(name_or_file, (str, Path)) and str(name_or_file).endswith(".toml"):
        return load_board_file(name_or_file)
    try:
        return lookup(__getattr__("BOARDS"), "board", name_or_file)
    except ValueError:
        raise BoardError(f"board must be one of {', '.join(BOARD_NAMES)} or a board file (.toml), "
                         f"not {name_or_file!r}") from None


# -- the project's board files -----------------------------------------------------------------

#: keys of a board file: key -> (required, what the value must be)
BOARD_FILE_KEYS = {
    "name": (True, "a name of letters, digits and '-'"),
    "family": (True, "one of " + ", ".join(IO_STANDARDS)),
    "device": (True, "a device name"),
    "package": (True, "a package name"),
    "speed": (False, "one of " + ", ".join(ECP5_SPEEDS) + " (ECP5 only)"),
    "io_standard": (True, "an I/O standard"),
    "programmer": (True, "an openFPGALoader board name"),
    "clock_pin": (True, "a pin name"),
    "clock_hz": (True, "a positive integer (Hz)"),
    "uart_rx": (True, "a pin name"),
    "uart_tx": (True, "a pin name"),
    "led_pin": (True, "a pin name"),
    "led_active_low": (False, "true or false"),
    "servo_pins": (True, "a non-empty list of pin names"),
}

_PIN = re.compile(r"[A-Za-z0-9_]+")


def _vendor_table(family: str, table: str) -> dict:
    """A table of Amaranth's vendor platform for ``family`` (the devices and packages it builds)."""
    import amaranth.vendor as vendor
    cls = vendor.SiliconBluePlatform if family == "ice40" else vendor.LatticePlatform
    return getattr(cls, table)


def _check_value(where: str, key: str, v, family: str | None):
    """Raise BoardError if ``v`` is not what key ``key`` must be."""
    what = BOARD_FILE_KEYS[key][1]
    ok = isinstance(v, str) and bool(v)
    if key == "name":
        ok = ok and re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9-]*", v) is not None
    elif key == "family":
        ok = v in IO_STANDARDS
    elif key == "device":
        choices = list(_vendor_table(family, "_nextpnr_device_options"))
        what, ok = "one of " + ", ".join(choices), v in choices
    elif key == "package" and family == "ecp5":
        choices = list(_vendor_table(family, "_nextpnr_package_options"))
        what, ok = "one of " + ", ".join(choices), v in choices
    elif key == "speed":
        ok = family == "ecp5" and v in ECP5_SPEEDS
    elif key == "io_standard":
        what, ok = "one of " + ", ".join(IO_STANDARDS[family]), v in IO_STANDARDS[family]
    elif key in ("clock_pin", "uart_rx", "uart_tx", "led_pin"):
        ok = ok and _PIN.fullmatch(v) is not None
    elif key == "clock_hz":
        ok = isinstance(v, int) and not isinstance(v, bool) and v > 0
    elif key == "led_active_low":
        ok = isinstance(v, bool)
    elif key == "servo_pins":
        ok = isinstance(v, list) and bool(v) and all(isinstance(p, str) and _PIN.fullmatch(p) for p in v)
    if not ok:
        raise BoardError(f"{where}{key} must be {what}, not {v!r}")


def parse_board(table: dict, where: str = "") -> Board:
    """A :class:`Board` from the keys of a board file (``where`` prefixes every error)."""
    if not isinstance(table, dict):
        raise BoardError(f"{where}a board file must be a table of keys, not {table!r}")
    for key in table:
        if key not in BOARD_FILE_KEYS:
            raise BoardError(f"{where}key must be one of {', '.join(BOARD_FILE_KEYS)}, not {key!r}")
    for key, (required, what) in BOARD_FILE_KEYS.items():
        if required and key not in table:
            raise BoardError(f"{where}{key} is missing: it must be {what}")
    _check_value(where, "family", table["family"], None)
    family = table["family"]
    if family == "ecp5" and "speed" not in table:
        raise BoardError(f"{where}speed is missing: it must be {BOARD_FILE_KEYS['speed'][1]}")
    for key in BOARD_FILE_KEYS:
        if key in table:
            _check_value(where, key, table[key], family)
    pins = [("clock_pin", table["clock_pin"]), ("uart_rx", table["uart_rx"]), ("uart_tx", table["uart_tx"]),
            ("led_pin", table["led_pin"])] + [("servo_pins", p) for p in table["servo_pins"]]
    seen: dict[str, str] = {}
    for key, pin in pins:
        if pin in seen:
            raise BoardError(f"{where}{key} must name a pin no other key uses, not {pin!r} "
                             f"(already {seen[pin]})")
        seen[pin] = key
    return Board(
        name=table["name"], family=family, device=table["device"], package=table["package"],
        speed=table.get("speed", ""), clock_pin=table["clock_pin"], clock_hz=table["clock_hz"],
        uart_rx=table["uart_rx"], uart_tx=table["uart_tx"], led=table["led_pin"],
        led_active_low=table.get("led_active_low", False),
        servo_pins=tuple((p, p) for p in table["servo_pins"]), io_standard=table["io_standard"],
        programmer=table["programmer"], source=where.rstrip(": "))


def board_file_text(board: Board) -> str:
    """The board file describing ``board`` (servo pins as package pins): a template for a
    board of one's own, and what :func:`parse_board` reads back to the same facts."""
    def val(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, int):
            return str(v)
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    table = {"name": board.name, "family": board.family, "device": board.device, "package": board.package,
             **({"speed": board.speed} if board.family == "ecp5" else {}),
             "io_standard": board.io_standard, "programmer": board.programmer, "clock_pin": board.clock_pin,
             "clock_hz": board.clock_hz, "uart_rx": board.uart_rx, "uart_tx": board.uart_tx,
             "led_pin": board.led, "led_active_low": board.led_active_low,
             "servo_pins": [p for _, p in board.servo_pins]}
    return "".join(f"{k} = {val(v)}\n" for k, v in table.items())


def load_board_file(path) -> Board:
    """The :class:`Board` described by the TOML board file at ``path``."""
    path = Path(path)
    try:
        table = tomllib.loads(path.read_text())
    except OSError as e:
        raise BoardError(f"cannot read board file {str(path)!r}: {e.strerror}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise BoardError(f"board file {str(path)!r} is not TOML: {e}") from None
    return parse_board(table, f"board file {path}: ")
