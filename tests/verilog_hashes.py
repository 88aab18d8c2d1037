"""sha256 of the exported Verilog of every core configuration a refactoring must keep.

``python tests/verilog_hashes.py`` prints each configuration's hash beside the recorded one
(``tests/data/verilog_hashes.json``); ``--record`` rewrites the file; ``--only NAME[,NAME]``
limits the run. ``tests/test_verilog_hashes.py`` checks the configurations whose plans the test
suite fits anyway by default, and all of them with ``pytest --all-hashes``.
"""
from __future__ import annotations

from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS

import argparse
import hashlib
import json
import sys
from pathlib import Path

from ikseries.fit.baselines.cordic import CordicDesign

RECORD = Path(__file__).with_name("data") / "verilog_hashes.json"

#: configuration -> (preset, hardware options (as ``ikseries build`` flags set them), kind).
#: kind "core": the build's own core choice; "cordic" / "cordic_iter": the CORDIC leg solver of
#: the tests' sized design, pipelined / iterative.
CONFIGS = {
    "default": ("cylinder-leg", {}, "core"),
    "pipelined": ("cylinder-leg", {"architecture": "pipelined"}, "core"),
    "folded1": ("cylinder-leg", {"architecture": "folded", "multipliers": 1}, "core"),
    "folded2": ("cylinder-leg", {"architecture": "folded", "multipliers": 2}, "core"),
    **{f"modulo{ii}": ("cylinder-leg", {"architecture": "modulo", "interval": ii}, "core") for ii in (4, 8, 16)},
    **{f"modulo{ii}_ecp5": ("cylinder-leg", {"architecture": "modulo", "interval": ii, "dsp": "ecp5"}, "core")
       for ii in (4, 8, 16)},
    **{f"modulo{ii}d": ("cylinder-leg", {"architecture": "modulo", "interval": ii, "dsp": "ecp5",
                                         "products": "dsp"}, "core") for ii in (4, 8, 16)},
    **{f"modulo{ii}d_prim": ("cylinder-leg", {"architecture": "modulo", "interval": ii, "dsp": "ecp5",
                                              "products": "dsp", "dsp_primitives": True}, "core")
       for ii in (4, 8, 16)},
    "hexapod": ("hexapod", {}, "core"),
    "hexapod-leg": ("hexapod-leg", {}, "core"),
    "planar-arm": ("planar-arm", {}, "core"),
    "quadruped-fore": ("quadruped-fore", {}, "core"),
    "quadruped-hind": ("quadruped-hind", {}, "core"),
    "cordic": ("cylinder-leg", {}, "cordic"),
    "cordic_iter": ("cylinder-leg", {}, "cordic_iter"),
}

#: configurations whose plans the test suite fits anyway (the default cylinder-leg plan)
QUICK = ("default", "pipelined", "folded1", "folded2", "modulo4", "modulo8", "modulo16",
         "modulo4_ecp5", "modulo8_ecp5", "modulo16_ecp5", "cordic", "cordic_iter")


def robot_of(name: str):
    from ikseries.robot import load_preset, with_fit, with_hardware
    preset, opts, _ = CONFIGS[name]
    robot = load_preset(preset)
    if opts.get("architecture") not in (None, "fastest"):
        opts = {"fit_device": None, **opts}
    fit = {k: v for k, v in opts.items() if k == "products"}
    hardware = {k: v for k, v in opts.items() if k != "products"}
    robot = with_fit(robot, **fit) if fit else robot
    return with_hardware(robot, **hardware) if hardware else robot


_PLANS: dict = {}   # fit-relevant robot record (JSON) -> fitted plan
#: the CORDIC design the tests use (``size_cordic`` of cylinder-leg on its verification points)
SIZED = CordicDesign(rot_iters=13, xy_iters=13, uv_iters=14, law_iters=13, len_frac=11, area_frac=3,
                     angle_frac=11, gain_frac=18, scale_frac=0)


def plan_of(name: str, plan=None):
    """The fitted plan of configuration ``name`` (``plan``: the already fitted one to use)."""
    if plan is not None:
        return plan
    from ikseries.fit.fitter import fit_robot
    robot = robot_of(name)
    key = json.dumps(robot.fit_record(), sort_keys=True)
    if key not in _PLANS:
        _PLANS[key] = fit_robot(robot)[0]
    return _PLANS[key]


def verilog_of(name: str, plan=None) -> str:
    """Exported Verilog of configuration ``name``, as ``ikseries build`` writes it."""
    from ikseries.architecture import choose_architecture
    from ikseries.hdl.export import leg_verilog, module_name, robot_verilog
    from ikseries.hdl.shared import RobotCore
    robot = robot_of(name)
    kind = CONFIGS[name][2]
    if kind != "core":
        from ikseries.hdl.cordic import CordicLegSolver
        from ikseries.hdl.flat import stream_verilog
        core = CordicLegSolver(robot, SIZED, 1 if kind == "cordic" else 17)
        return stream_verilog(core, "cordic_solver")
    core = choose_architecture(robot, plan_of(name, plan)).core
    mod = module_name(robot.name)
    return robot_verilog(core, mod) if isinstance(core, RobotCore) else leg_verilog(core, mod)


def sha256_of(name: str, plan=None) -> str:
    return hashlib.sha256(verilog_of(name, plan).encode()).hexdigest()


def recorded() -> dict:
    return json.loads(RECORD.read_text())


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--record", action="store_true", help="rewrite tests/data/verilog_hashes.json")
    p.add_argument("--only", help="comma-separated configuration names")
    args = p.parse_args(argv)
    names = args.only.split(",") if args.only else list(CONFIGS)
    bad = [n for n in names if n not in CONFIGS]
    if bad:
        print(f"--only must name configurations from {', '.join(CONFIGS)}, not {bad[0]!r}", file=sys.stderr)
        return 2
    old = recorded() if RECORD.exists() else {}
    new, changed = dict(old), 0
    for n in names:
        h = sha256_of(n)
        state = "same" if old.get(n) == h else ("new" if n not in old else "CHANGED")
        changed += state == "CHANGED"
        print(f"{n:18} {h} {state}", flush=True)
        new[n] = h
    if args.record:
        RECORD.write_text(json.dumps(dict(sorted(new.items())), indent=1) + "\n")
    return 1 if changed and not args.record else 0


if __name__ == "__main__":
    sys.exit(main())
